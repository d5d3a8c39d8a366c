// The option table: each option declared once gives its parsing, its range check, the
// equivalent command (what differs from the defaults) and its row in the docs.
#include "base/option_table.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>

namespace procam {
namespace {

enum class Shade { kRed, kGreen, kBlue };

struct Settings {
  double alpha = 0.5;
  int rounds = 4;
  bool fast = false;
  bool smooth = true;
  std::string label = "room";
  std::filesystem::path out;
  Shade shade = Shade::kGreen;

  void Declare(OptionTable* table) {
    table->Number("alpha", &alpha, 1e-9, 1.0, "", "weight of the absolute term")
        .Integer("rounds", &rounds, 1, 100, "", "metric rounds")
        .Flag("fast", &fast, "solve the coarse level first")
        .Flag("smooth", &smooth, "shape the light within each patch")
        .Text("label", &label, "a name")
        .Path("out", &out, "output directory")
        .Choice("shade", &shade,
                {{"red", Shade::kRed}, {"green", Shade::kGreen}, {"blue", Shade::kBlue}},
                "the colour");
  }
};

TEST(OptionTable, DefaultsAreValidAndChangeNothing) {
  Settings settings;
  OptionTable table("test");
  settings.Declare(&table);
  std::string why;
  EXPECT_TRUE(table.Check(&why)) << why;
  EXPECT_TRUE(table.ChangedArguments().empty());
  ASSERT_NE(table.Find("alpha"), nullptr);
  EXPECT_EQ(table.Find("alpha")->default_text, "0.5");
  EXPECT_EQ(table.Find("shade")->default_text, "green");
  EXPECT_EQ(table.Find("missing"), nullptr);
}

TEST(OptionTable, SetParsesIntoTheFieldsAndTheEquivalentCommandReadsBack) {
  Settings settings;
  OptionTable table("test");
  settings.Declare(&table);
  table.Set("alpha", "0.1");  // not exactly representable: written back as the shortest text
  table.Set("rounds", "7");
  table.Set("smooth", "false");
  table.Set("fast", "");
  table.Set("shade", "blue");
  table.Set("out", "dir/sub");
  EXPECT_EQ(settings.alpha, 0.1);
  EXPECT_EQ(settings.rounds, 7);
  EXPECT_TRUE(settings.fast);
  EXPECT_FALSE(settings.smooth);
  EXPECT_EQ(settings.shade, Shade::kBlue);
  EXPECT_EQ(settings.out, "dir/sub");
  const std::vector<std::string> expected = {
      "--alpha",        "0.1",   "--rounds", "7",       "--fast",
      "--smooth=false", "--out", "dir/sub",  "--shade", "blue"};
  EXPECT_EQ(table.ChangedArguments(), expected);

  // The printed command, read by a table of fresh defaults, gives the same settings.
  Settings again;
  OptionTable reader("test");
  again.Declare(&reader);
  const std::vector<std::string> arguments = table.ChangedArguments();
  for (size_t i = 0; i < arguments.size(); ++i) {
    std::string name = arguments[i].substr(2), value;
    if (const size_t equals = name.find('='); equals != std::string::npos) {
      value = name.substr(equals + 1);
      name = name.substr(0, equals);
    } else if (reader.Find(name)->kind != OptionTable::Kind::kFlag) {
      value = arguments[++i];
    }
    reader.Set(name, value);
  }
  EXPECT_EQ(again.alpha, settings.alpha);
  EXPECT_EQ(again.rounds, settings.rounds);
  EXPECT_EQ(again.fast, settings.fast);
  EXPECT_EQ(again.smooth, settings.smooth);
  EXPECT_EQ(again.shade, settings.shade);
  EXPECT_EQ(again.out, settings.out);
}

TEST(OptionTable, RefusesValuesOutsideTheDeclarationNamingTheFlag) {
  Settings settings;
  OptionTable table("test");
  settings.Declare(&table);
  auto message = [&](const std::string& name, const std::string& text) {
    try {
      table.Set(name, text);
    } catch (const std::invalid_argument& error) {
      return std::string(error.what());
    }
    return std::string("accepted");
  };
  EXPECT_EQ(message("alpha", "2"), "--alpha: must be in [1e-09, 1], got 2");
  EXPECT_EQ(message("alpha", "nan"), "--alpha: expected a finite number, got 'nan'");
  EXPECT_EQ(message("alpha", "0.5x"), "--alpha: expected a finite number, got '0.5x'");
  EXPECT_EQ(message("rounds", "2.5"), "--rounds: expected a whole number, got '2.5'");
  EXPECT_EQ(message("rounds", "0"), "--rounds: must be in [1, 100], got 0");
  EXPECT_EQ(message("shade", "pink"), "--shade: expected red, green, blue; got 'pink'");
  EXPECT_EQ(message("fast", "maybe"), "--fast: expected true or false, got 'maybe'");
  EXPECT_EQ(message("colour", "red"), "test: no option --colour");
  // A refused value leaves the field as it was.
  EXPECT_EQ(settings.alpha, 0.5);
  EXPECT_EQ(settings.rounds, 4);
}

TEST(OptionTable, CheckFindsFieldsSetOutsideTheTable) {
  Settings settings;
  OptionTable table("test");
  settings.Declare(&table);
  std::string why;
  settings.rounds = 101;
  EXPECT_FALSE(table.Check(&why));
  EXPECT_EQ(why, "--rounds: must be in [1, 100], got 101");
  settings.rounds = 4;
  settings.alpha = std::numeric_limits<double>::quiet_NaN();
  EXPECT_FALSE(table.Check(&why));
  EXPECT_EQ(why, "--alpha: must be a finite number, got nan");
  settings.alpha = 0.5;
  settings.shade = static_cast<Shade>(7);
  EXPECT_FALSE(table.Check(&why));
  EXPECT_EQ(why, "--shade: holds a value that is none of red, green, blue");
}

TEST(OptionTable, OpenEndsAndNegatedFlags) {
  double step = 1.0;
  bool fit = true;
  OptionTable table("test");
  table.Number("step", &step, OptionTable::Interval::AboveMin(0.0, 1.0), "", "damping")
      .NegatedFlag("no-fit", &fit, "leave it");
  EXPECT_EQ(table.Find("no-fit")->default_text, "false");
  EXPECT_THROW(table.Set("step", "0"), std::invalid_argument);  // (0, 1]: 0 is outside
  table.Set("step", "1");
  table.Set("no-fit", "");
  EXPECT_FALSE(fit);
  const std::vector<std::string> expected = {"--no-fit"};
  EXPECT_EQ(table.ChangedArguments(), expected);
  step = 0.0;
  std::string why;
  EXPECT_FALSE(table.Check(&why));
  EXPECT_EQ(why, "--step: must be in (0, 1], got 0");
  EXPECT_EQ(OptionTable::Interval::BelowMax(0.0, 1.0).Text(), "[0, 1)");
  EXPECT_FALSE(OptionTable::Interval::BelowMax(0.0, 1.0).Contains(1.0));
  EXPECT_TRUE(OptionTable::Interval::BelowMax(0.0, 1.0).Contains(0.0));
}

TEST(OptionTable, NamesAreUnique) {
  Settings settings;
  OptionTable table("test");
  settings.Declare(&table);
  EXPECT_THROW(table.Flag("fast", &settings.fast, "again"), std::invalid_argument);
  EXPECT_THROW(table.Flag("--dashed", &settings.fast, "dashes"), std::invalid_argument);
}

TEST(OptionTable, MarkdownHasARowPerOptionWithItsDefaultAndValues) {
  Settings settings;
  OptionTable table("test");
  settings.Declare(&table);
  const std::string markdown = table.Markdown();
  EXPECT_NE(
      markdown.find("| `--alpha` | `0.5` | number in [1e-09, 1] | weight of the absolute term |"),
      std::string::npos)
      << markdown;
  EXPECT_NE(markdown.find("| `--shade` | `green` | red \\| green \\| blue | the colour |"),
            std::string::npos)
      << markdown;
  EXPECT_NE(markdown.find("| `--fast` | `false` | flag |"), std::string::npos) << markdown;
  EXPECT_EQ(std::count(markdown.begin(), markdown.end(), '\n'), 2 + 7);
}

// Lists, positional and required options, unset numbers and values of their own syntax: what a
// stage's printed command needs (sessions, --out, --names a,b, --hold-lens x=1 --hold-lens y=2).
struct Step {
  std::vector<std::filesystem::path> sessions;
  std::filesystem::path out;
  std::vector<std::string> names;
  std::vector<std::string> entries;
  std::vector<int> levels = {0, 255};
  std::vector<double> exposures;
  std::optional<double> gain;
  double settle = 150.0;
  bool measure = false;

  void Declare(OptionTable* table) {
    bool* measured = &measure;
    double* ms = &settle;
    table->Paths("sessions", &sessions, "sessions")
        .Positional()
        .Required()
        .Path("out", &out, "output")
        .Required()
        .Texts("names", &names, "names")
        .Texts("entry", &entries, "entries")
        .Repeated()
        .Integers("levels", &levels, 0, 255, "", "levels")
        .Numbers("exposure", &exposures, OptionTable::Interval::AboveMin(0.0, 1e8), "us",
                 "exposures")
        .OptionalNumber("gain", &gain, OptionTable::Interval::Closed(0.0, 10.0), "dB", "gain")
        .Integer("count", &unbounded, 0, std::numeric_limits<int>::max(), "", "at least none")
        .Custom(
            "settle", [=] { return *measured ? std::string("auto") : OptionNumberText(*ms); },
            [=](const std::string& text, std::string* why) {
              if (text == "auto") return *measured = true;
              *measured = false;
              if (text != "0" && text != "5") {
                *why = "auto, 0 or 5";
                return false;
              }
              *ms = std::stod(text);
              return true;
            },
            "auto, 0 or 5", "settle");
  }
  int unbounded = 0;
};

TEST(OptionTable, ListsPositionalsRequiredUnsetAndCustomOptions) {
  Step step;
  OptionTable table("step");
  step.Declare(&table);
  std::string why;
  EXPECT_FALSE(table.Check(&why));  // the sessions are required
  EXPECT_EQ(why, "sessions is required");
  table.Set("sessions", "a,b");
  EXPECT_FALSE(table.Check(&why));
  EXPECT_EQ(why, "--out is required");
  table.Set("out", "rig");
  EXPECT_TRUE(table.Check(&why)) << why;
  EXPECT_EQ(step.sessions, (std::vector<std::filesystem::path>{"a", "b"}));
  EXPECT_EQ(table.Find("levels")->default_text, "0,255");
  EXPECT_EQ(table.Find("gain")->default_text, "");
  EXPECT_EQ(table.Find("settle")->default_text, "150");

  table.Set("names", "left,right");
  table.Set("entry", "x=1,2");  // one item per flag: commas kept
  step.entries.push_back("y=3");
  table.Set("levels", "0,128,255");
  table.Set("gain", "2.5");
  table.Set("settle", "auto");
  EXPECT_EQ(step.names, (std::vector<std::string>{"left", "right"}));
  EXPECT_EQ(step.levels, (std::vector<int>{0, 128, 255}));
  ASSERT_TRUE(step.gain.has_value());
  EXPECT_EQ(*step.gain, 2.5);
  EXPECT_TRUE(step.measure);
  EXPECT_EQ(table.ChangedArguments(),
            (std::vector<std::string>{"a", "b", "--out", "rig", "--names", "left,right", "--entry",
                                      "x=1,2", "--entry", "y=3", "--levels", "0,128,255", "--gain",
                                      "2.5", "--settle", "auto"}));

  // The same from a copy of the struct, as a stage prints the command for a step it runs.
  EXPECT_EQ(ChangedArgumentsOf(step), table.ChangedArguments());

  // Refusals name the flag (Set) and leave the field.
  EXPECT_THROW(table.Set("levels", "0,300"), std::invalid_argument);
  EXPECT_EQ(step.levels, (std::vector<int>{0, 128, 255}));
  try {
    table.Set("exposure", "100,-1");
    ADD_FAILURE() << "a negative exposure was accepted";
  } catch (const std::invalid_argument& error) {
    EXPECT_EQ(std::string(error.what()), "--exposure: must be in (0, 100000000], got -1");
  }
  try {
    table.Set("count", "-1");
    ADD_FAILURE() << "a negative count was accepted";
  } catch (const std::invalid_argument& error) {
    EXPECT_EQ(std::string(error.what()), "--count: must be >= 0, got -1");
  }
  EXPECT_THROW(table.Set("settle", "7"), std::invalid_argument);
  EXPECT_THROW(table.Set("gain", "11"), std::invalid_argument);
  table.Set("gain", "");  // unset again
  EXPECT_FALSE(step.gain.has_value());
  step.exposures = {std::nan("")};
  EXPECT_FALSE(table.Check(&why));
  EXPECT_NE(why.find("--exposure: must be finite"), std::string::npos) << why;

  const std::string markdown = table.Markdown();
  EXPECT_NE(markdown.find("| `sessions` |  | list of paths, required | sessions |"),
            std::string::npos)
      << markdown;
  EXPECT_NE(markdown.find("| `--count` | `0` | whole number in [0, ∞) | at least none |"),
            std::string::npos)
      << markdown;
  EXPECT_NE(markdown.find("| `--settle` | `150` | auto, 0 or 5 | settle |"), std::string::npos)
      << markdown;
}

// A message names an option from its declaration: the option that sets a field, found by the
// field's address (each kind of option, a positional one by its name, a Custom one by the fields
// Sets() names), on the struct itself or through FlagOf(options, &options.field).
TEST(OptionTable, FlagOfNamesTheOptionThatSetsAField) {
  Settings settings;
  OptionTable table("settings");
  settings.Declare(&table);
  EXPECT_EQ(table.FlagOf(&settings.alpha), "--alpha");
  EXPECT_EQ(table.FlagOf(&settings.rounds), "--rounds");
  EXPECT_EQ(table.FlagOf(&settings.smooth), "--smooth");
  EXPECT_EQ(table.FlagOf(&settings.out), "--out");
  EXPECT_EQ(table.FlagOf(&settings.shade), "--shade");
  EXPECT_EQ(FlagOf(settings, &settings.label), "--label");

  Step step;
  EXPECT_EQ(FlagOf(step, &step.sessions), "sessions");  // positional: its name alone
  EXPECT_EQ(FlagOf(step, &step.entries), "--entry");
  EXPECT_EQ(FlagOf(step, &step.levels), "--levels");
  EXPECT_EQ(FlagOf(step, &step.exposures), "--exposure");
  EXPECT_EQ(FlagOf(step, &step.gain), "--gain");
  // A Custom option sets no field the table sees, until Sets() names them.
  EXPECT_THROW(FlagOf(step, &step.measure), std::logic_error);
  OptionTable custom("step");
  step.Declare(&custom);
  custom.Sets(&step.measure).Sets(&step.settle);
  EXPECT_EQ(custom.FlagOf(&step.measure), "--settle");
  EXPECT_EQ(custom.FlagOf(&step.settle), "--settle");
  // A field of another struct is no option of this table.
  Settings other;
  EXPECT_THROW(table.FlagOf(&other.alpha), std::logic_error);
}

}  // namespace
}  // namespace procam
