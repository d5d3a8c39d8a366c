#pragma once
// Each option of a stage declared once. A stage's Options struct lists its options in an
// OptionTable — the flag's name, the field it sets, its range or choices, its unit and its help —
// and everything else comes from that one declaration: the command line (apps/ binds each flag
// straight to its field), the range checks of Check(), the equivalent command a stage prints
// (only what differs from the defaults) and the option tables of docs/options.md (`procam
// options`). As COLMAP's OptionManager binds flags to struct fields, and as Ceres documents each
// option beside its field.
//
//   OptionTable table("compensate");
//   table.Number("alpha", &options.alpha, 1e-9, 1.0, "", "weight of the absolute term");
//   table.Choice("method", &options.method, {{"linear", kLinear}, {"perceptual", kPerceptual}},
//                "the objective");
//   std::string why;
//   if (!table.Check(&why)) ...            // "--alpha: must be in [1e-09, 1], got 2"
//   table.ChangedArguments()               // {"--alpha", "0.3"}: what differs from the defaults
//
// A table holds pointers to the fields it was built on: it lives no longer than they do, and a
// copy of the Options struct needs a table of its own (each struct's Declare(OptionTable*)).

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace procam {

class OptionTable {
 public:
  enum class Kind { kFlag, kInteger, kNumber, kText, kPath, kChoice, kList, kCustom };

  // The values a number takes: [min, max], with either end open ("(0, 1]").
  struct Interval {
    double min = 0.0, max = 0.0;
    bool min_open = false, max_open = false;
    static Interval Closed(double min, double max) { return {min, max, false, false}; }
    static Interval AboveMin(double min, double max) { return {min, max, true, false}; }
    static Interval BelowMax(double min, double max) { return {min, max, false, true}; }
    bool Contains(double value) const;
    std::string Text() const;  // "[0, 1)"
  };

  struct Option {
    std::string name;  // the flag without its dashes, e.g. "loss-scale"
    Kind kind = Kind::kText;
    std::string help;                  // one sentence, lower case, no final full stop
    std::string unit;                  // e.g. "ms", "m", "ΔE00"; empty if none
    std::optional<Interval> range;     // kInteger, kNumber
    std::vector<std::string> choices;  // kChoice: the names accepted, in the order declared
    std::string default_text;          // the field's value when declared, as written
    // The field's value as written on a command line ("true"/"false" for a flag).
    std::function<std::string()> get;
    // Parses `text` into the field: false and `*why` (without the flag's name) if it is not a
    // value of this option (not a number, out of range, not one of the choices).
    std::function<bool(const std::string& text, std::string* why)> set;
    // The field's value is within the declared range or choices; `*why` as for set.
    std::function<bool(std::string* why)> check;
    bool required = false;    // must be given (Required())
    bool positional = false;  // given without its flag, in the order declared (Positional())
    // kList: the items, each as written; get() and set() take them joined by ','.
    std::function<std::vector<std::string>()> items;
    std::function<bool(const std::vector<std::string>& items, std::string* why)> set_items;
    bool repeated = false;  // kList: one item per flag ("--hold-lens a=x --hold-lens b=y")
    std::string values;     // kList, kCustom: what it takes, e.g. "auto or ms in [0, 60000]"
    // The fields it sets, by which FlagOf finds it: the one it was declared on (a Custom or a
    // List: those Sets() names).
    std::vector<const void*> fields;
  };

  // `owner` names the table in docs/options.md and in messages, e.g. "compensate".
  explicit OptionTable(std::string owner = "") : owner_(std::move(owner)) {}

  // Each adds an option bound to `field` and returns the table (for the next declaration).
  // Names are unique within a table (std::invalid_argument otherwise).
  OptionTable& Flag(const std::string& name, bool* field, const std::string& help);
  OptionTable& Integer(const std::string& name, int* field, int min, int max,
                       const std::string& unit, const std::string& help);
  OptionTable& Number(const std::string& name, double* field, double min, double max,
                      const std::string& unit, const std::string& help) {
    return Number(name, field, Interval::Closed(min, max), unit, help);
  }
  OptionTable& Number(const std::string& name, double* field, Interval range,
                      const std::string& unit, const std::string& help);
  // A flag that clears `field` when given: "--no-response-fit" for a field on by default.
  OptionTable& NegatedFlag(const std::string& name, bool* field, const std::string& help);
  OptionTable& Text(const std::string& name, std::string* field, const std::string& help);
  OptionTable& Path(const std::string& name, std::filesystem::path* field, const std::string& help);
  // A number that may be unset (empty when written).
  OptionTable& OptionalNumber(const std::string& name, std::optional<double>* field, Interval range,
                              const std::string& unit, const std::string& help);
  // Lists, given as one comma-separated value or by repeating the flag ("--names a,b" or
  // "--names a --names b"); written as one comma-separated value.
  OptionTable& Texts(const std::string& name, std::vector<std::string>* field,
                     const std::string& help);
  OptionTable& Paths(const std::string& name, std::vector<std::filesystem::path>* field,
                     const std::string& help);
  OptionTable& Numbers(const std::string& name, std::vector<double>* field, Interval range,
                       const std::string& unit, const std::string& help);
  OptionTable& Integers(const std::string& name, std::vector<int>* field, int min, int max,
                        const std::string& unit, const std::string& help);
  // A list of any items: `items` writes them, `set_items` parses them into the field. `values`
  // says what an item is.
  OptionTable& List(const std::string& name, std::function<std::vector<std::string>()> items,
                    std::function<bool(const std::vector<std::string>&, std::string*)> set_items,
                    const std::string& values, const std::string& help);
  // A value of its own syntax (e.g. "auto" or milliseconds; "9x6"), possibly spread over several
  // fields: `get` writes it, `set` parses it (false and `*why` if it is not a value of it), and
  // `values` says what it takes.
  OptionTable& Custom(const std::string& name, std::function<std::string()> get,
                      std::function<bool(const std::string&, std::string*)> set,
                      const std::string& values, const std::string& help);
  // Modify the option declared last: it must be given (the command line requires it; Check()
  // refuses it empty); it is given without its flag, in the order declared (a list takes every
  // such value left); a list given one item per flag, its items not split at commas.
  OptionTable& Required();
  OptionTable& Positional();
  OptionTable& Repeated();
  // The option declared last sets `field` (a Custom or a List, whose field the table does not
  // see): FlagOf(field) names it.
  OptionTable& Sets(const void* field);
  // An enumeration by name: `names` pairs each accepted name with its value.
  template <typename Enum>
  OptionTable& Choice(const std::string& name, Enum* field,
                      const std::vector<std::pair<std::string, Enum>>& names,
                      const std::string& help);

  const std::string& owner() const { return owner_; }
  const std::vector<Option>& options() const { return options_; }
  // The option named `name` (without dashes), or nullptr.
  const Option* Find(const std::string& name) const;
  // The option that sets `field`, as messages write it: "--camera-guess", or a positional's name.
  // Throws std::logic_error when no option sets it (a message naming an undeclared field).
  std::string FlagOf(const void* field) const;

  // Every field within its declared range or choices. On failure `*why` is one line naming the
  // flag: "--alpha: must be in [1e-09, 1], got 2".
  bool Check(std::string* why) const;
  // The options whose value differs from their default, as a command line writes them, in the
  // order declared: {"--alpha", "0.3", "--multires"}; a positional option as its value(s) alone.
  std::vector<std::string> ChangedArguments() const;
  // Sets an option from its written value (as the command line does). Throws
  // std::invalid_argument naming the flag: no such option, or a value it does not take.
  void Set(const std::string& name, const std::string& text);
  // A Markdown table: option | default | values | help.
  std::string Markdown() const;

 private:
  Option& Add(const std::string& name, Kind kind, const std::string& help);
  void AddChoice(const std::string& name, std::vector<std::string> choices,
                 std::function<int()> get_index, std::function<void(int)> set_index,
                 const std::string& help);

  Option& Last(const char* what);

  std::string owner_;
  std::vector<Option> options_;
};

// The command line equivalent to `options`: what differs from a default-constructed Options, as
// its Declare(OptionTable*) declares it (OptionTable::ChangedArguments). E.g. the command a stage
// prints for a step it runs.
template <typename Options>
std::vector<std::string> ChangedArgumentsOf(const Options& options) {
  Options copy;  // the table's defaults: the struct's own
  OptionTable table;
  copy.Declare(&table);
  copy = options;  // the fields the table points to now hold `options`' values
  return table.ChangedArguments();
}

// OptionTable::Check of `options`' declared options (on a copy: the table binds its fields).
template <typename Options>
bool CheckDeclared(const Options& options, std::string* why) {
  Options copy = options;
  OptionTable table;
  copy.Declare(&table);
  return table.Check(why);
}

// The option of `options` that sets `field` (a member of `options`), as messages write it
// (OptionTable::FlagOf): a library message names an option from its declaration, e.g.
// FlagOf(options, &options.camera_guess) is "--camera-guess". `declare`: as AddDeclaredOptions'.
template <typename Options>
std::string FlagOf(const Options& options, const void* field,
                   void (Options::*declare)(OptionTable*) = &Options::Declare) {
  OptionTable table;
  (const_cast<Options&>(options).*declare)(&table);  // the table only takes the fields' addresses
  return table.FlagOf(field);
}

// Writes a number as options are written: the shortest text that reads back to the same double.
std::string OptionNumberText(double value);

template <typename Enum>
OptionTable& OptionTable::Choice(const std::string& name, Enum* field,
                                 const std::vector<std::pair<std::string, Enum>>& names,
                                 const std::string& help) {
  std::vector<std::string> choices;
  for (const auto& [text, value] : names) choices.push_back(text);
  AddChoice(
      name, std::move(choices),
      [field, names] {
        for (size_t i = 0; i < names.size(); ++i) {
          if (names[i].second == *field) return static_cast<int>(i);
        }
        return -1;
      },
      [field, names](int index) { *field = names[static_cast<size_t>(index)].second; }, help);
  return Sets(field);
}

}  // namespace procam
