#include "base/option_table.h"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <system_error>

namespace procam {
namespace {

std::string ChoicesText(const std::vector<std::string>& choices, const char* separator) {
  std::string text;
  for (size_t i = 0; i < choices.size(); ++i) text += (i ? separator : "") + choices[i];
  return text;
}

// The whole of `text` as a finite double; false otherwise ("1e", "nan", "inf", "").
bool ParseFinite(const std::string& text, double* value) {
  const char* end = text.data() + text.size();
  const auto [last, error] = std::from_chars(text.data(), end, *value);
  return error == std::errc() && last == end && std::isfinite(*value);
}

// No upper end: an Integer up to INT_MAX, a Number up to infinity.
bool Unbounded(const OptionTable::Interval& range) {
  return range.max >= static_cast<double>(std::numeric_limits<int>::max());
}

bool InRange(const OptionTable::Interval& range, double value, std::string* why) {
  if (range.Contains(value)) return true;
  if (Unbounded(range) && value <= range.min) {
    *why = fmt::format("must be {} {}, got {}",
                       range.min_open ? ">" : ">=", OptionNumberText(range.min),
                       OptionNumberText(value));
  } else {
    *why = fmt::format("must be in {}, got {}", range.Text(), OptionNumberText(value));
  }
  return false;
}

// A number's written value: finite and within `range`, else false with why.
bool ParseNumberInRange(const std::string& text, const OptionTable::Interval& range, double* value,
                        std::string* why) {
  if (!ParseFinite(text, value)) {
    *why = "expected a finite number, got '" + text + "'";
    return false;
  }
  return InRange(range, *value, why);
}

// A flag's written value ("", "true", "1", "false", "0") into `field`, inverted for a negated
// flag (--no-NAME given clears it).
bool ParseFlag(const std::string& text, bool negated, bool* field, std::string* why) {
  bool given = false;
  if (text == "true" || text == "1" || text.empty()) {
    given = true;
  } else if (!(text == "false" || text == "0")) {
    *why = "expected true or false, got '" + text + "'";
    return false;
  }
  *field = given != negated;
  return true;
}

std::vector<std::string> SplitItems(const std::string& text) {
  std::vector<std::string> items;
  size_t begin = 0;
  while (true) {
    const size_t comma = text.find(',', begin);
    items.push_back(text.substr(begin, comma == std::string::npos ? comma : comma - begin));
    if (comma == std::string::npos) return items;
    begin = comma + 1;
  }
}

// How an option is written in messages: "--name", or a positional's name alone.
std::string Written(const OptionTable::Option& option) {
  return option.positional ? option.name : "--" + option.name;
}

}  // namespace

bool OptionTable::Interval::Contains(double value) const {
  return (min_open ? value > min : value >= min) && (max_open ? value < max : value <= max);
}

std::string OptionTable::Interval::Text() const {
  if (Unbounded(*this)) return fmt::format("{}{}, ∞)", min_open ? "(" : "[", OptionNumberText(min));
  return fmt::format("{}{}, {}{}", min_open ? "(" : "[", OptionNumberText(min),
                     OptionNumberText(max), max_open ? ")" : "]");
}

std::string OptionNumberText(double value) {
  // Whole numbers as people write them ("600000", not "6e+05").
  if (std::isfinite(value) && value == std::floor(value) && std::abs(value) < 1e15) {
    return fmt::format("{}", static_cast<long long>(value));
  }
  char buffer[32];
  const auto [last, error] = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return error == std::errc() ? std::string(buffer, last) : fmt::format("{}", value);
}

OptionTable::Option& OptionTable::Add(const std::string& name, Kind kind, const std::string& help) {
  if (name.empty() || name[0] == '-' || Find(name) != nullptr) {
    throw std::invalid_argument("option table " + owner_ + ": option name '" + name +
                                "' is empty, starts with '-' or is declared twice");
  }
  Option& option = options_.emplace_back();
  option.name = name;
  option.kind = kind;
  option.help = help;
  option.check = [](std::string*) { return true; };
  return option;
}

OptionTable& OptionTable::Flag(const std::string& name, bool* field, const std::string& help) {
  Option& option = Add(name, Kind::kFlag, help);
  option.fields = {field};
  option.get = [field] { return std::string(*field ? "true" : "false"); };
  option.set = [field](const std::string& text, std::string* why) {
    return ParseFlag(text, /*negated=*/false, field, why);
  };
  option.default_text = option.get();
  return *this;
}

OptionTable& OptionTable::NegatedFlag(const std::string& name, bool* field,
                                      const std::string& help) {
  Option& option = Add(name, Kind::kFlag, help);
  option.fields = {field};
  option.get = [field] { return std::string(*field ? "false" : "true"); };
  option.set = [field](const std::string& text, std::string* why) {
    return ParseFlag(text, /*negated=*/true, field, why);
  };
  option.default_text = option.get();
  return *this;
}

OptionTable& OptionTable::Integer(const std::string& name, int* field, int min, int max,
                                  const std::string& unit, const std::string& help) {
  Option& option = Add(name, Kind::kInteger, help);
  option.fields = {field};
  option.unit = unit;
  const Interval range = Interval::Closed(min, max);
  option.range = range;
  option.get = [field] { return std::to_string(*field); };
  option.set = [field, range](const std::string& text, std::string* why) {
    int value = 0;
    const char* end = text.data() + text.size();
    const auto [last, error] = std::from_chars(text.data(), end, value);
    if (error != std::errc() || last != end) {
      *why = "expected a whole number, got '" + text + "'";
      return false;
    }
    if (!InRange(range, value, why)) return false;
    *field = value;
    return true;
  };
  option.check = [field, range](std::string* why) { return InRange(range, *field, why); };
  option.default_text = option.get();
  return *this;
}

OptionTable& OptionTable::Number(const std::string& name, double* field, Interval range,
                                 const std::string& unit, const std::string& help) {
  Option& option = Add(name, Kind::kNumber, help);
  option.fields = {field};
  option.unit = unit;
  option.range = range;
  option.get = [field] { return OptionNumberText(*field); };
  option.set = [field, range](const std::string& text, std::string* why) {
    double value = 0.0;
    if (!ParseNumberInRange(text, range, &value, why)) return false;
    *field = value;
    return true;
  };
  option.check = [field, range](std::string* why) {
    if (!std::isfinite(*field)) {
      *why = "must be a finite number, got " + OptionNumberText(*field);
      return false;
    }
    return InRange(range, *field, why);
  };
  option.default_text = option.get();
  return *this;
}

OptionTable& OptionTable::Text(const std::string& name, std::string* field,
                               const std::string& help) {
  Option& option = Add(name, Kind::kText, help);
  option.fields = {field};
  option.get = [field] { return *field; };
  option.set = [field](const std::string& text, std::string*) {
    *field = text;
    return true;
  };
  option.default_text = option.get();
  return *this;
}

OptionTable& OptionTable::Path(const std::string& name, std::filesystem::path* field,
                               const std::string& help) {
  Option& option = Add(name, Kind::kPath, help);
  option.fields = {field};
  option.get = [field] { return field->string(); };
  option.set = [field](const std::string& text, std::string*) {
    *field = text;
    return true;
  };
  option.default_text = option.get();
  return *this;
}

void OptionTable::AddChoice(const std::string& name, std::vector<std::string> choices,
                            std::function<int()> get_index, std::function<void(int)> set_index,
                            const std::string& help) {
  Option& option = Add(name, Kind::kChoice, help);
  option.choices = std::move(choices);
  const std::vector<std::string>& names = option.choices;
  option.get = [get_index, names] {
    const int index = get_index();
    return index < 0 ? std::string("(unnamed value)") : names[static_cast<size_t>(index)];
  };
  option.set = [set_index, names](const std::string& text, std::string* why) {
    for (size_t i = 0; i < names.size(); ++i) {
      if (names[i] == text) {
        set_index(static_cast<int>(i));
        return true;
      }
    }
    *why = "expected " + ChoicesText(names, ", ") + "; got '" + text + "'";
    return false;
  };
  option.check = [get_index, names](std::string* why) {
    if (get_index() >= 0) return true;
    *why = "holds a value that is none of " + ChoicesText(names, ", ");
    return false;
  };
  option.default_text = option.get();
}

OptionTable& OptionTable::OptionalNumber(const std::string& name, std::optional<double>* field,
                                         Interval range, const std::string& unit,
                                         const std::string& help) {
  Option& option = Add(name, Kind::kNumber, help);
  option.fields = {field};
  option.unit = unit;
  option.range = range;
  option.get = [field] { return *field ? OptionNumberText(**field) : std::string(); };
  option.set = [field, range](const std::string& text, std::string* why) {
    if (text.empty()) {
      field->reset();
      return true;
    }
    double value = 0.0;
    if (!ParseNumberInRange(text, range, &value, why)) return false;
    *field = value;
    return true;
  };
  option.check = [field, range](std::string* why) {
    if (!*field) return true;
    if (!std::isfinite(**field)) {
      *why = "must be a finite number, got " + OptionNumberText(**field);
      return false;
    }
    return InRange(range, **field, why);
  };
  option.default_text = option.get();
  return *this;
}

OptionTable& OptionTable::List(
    const std::string& name, std::function<std::vector<std::string>()> items,
    std::function<bool(const std::vector<std::string>&, std::string*)> set_items,
    const std::string& values, const std::string& help) {
  Option& option = Add(name, Kind::kList, help);
  option.values = values;
  option.items = items;
  option.set_items = set_items;
  option.get = [items] { return ChoicesText(items(), ","); };
  // Set() and the default's text: one value, split at commas (Repeated(): one item).
  option.set = [set_items](const std::string& text, std::string* why) {
    return set_items(text.empty() ? std::vector<std::string>() : SplitItems(text), why);
  };
  option.default_text = option.get();
  return *this;
}

namespace {

// Items parsed one by one into a vector of T.
template <typename T, typename Parse>
std::function<bool(const std::vector<std::string>&, std::string*)> SetEach(std::vector<T>* field,
                                                                           Parse parse) {
  return [field, parse](const std::vector<std::string>& items, std::string* why) {
    std::vector<T> values;
    for (const std::string& item : items) {
      T value{};
      if (!parse(item, &value, why)) return false;
      values.push_back(std::move(value));
    }
    *field = std::move(values);
    return true;
  };
}

template <typename T, typename Write>
std::function<std::vector<std::string>()> WriteEach(const std::vector<T>* field, Write write) {
  return [field, write] {
    std::vector<std::string> items;
    for (const T& value : *field) items.push_back(write(value));
    return items;
  };
}

}  // namespace

OptionTable& OptionTable::Texts(const std::string& name, std::vector<std::string>* field,
                                const std::string& help) {
  List(name, WriteEach(field, [](const std::string& text) { return text; }),
       SetEach(field,
               [](const std::string& item, std::string* value, std::string*) {
                 *value = item;
                 return true;
               }),
       "list of text", help);
  return Sets(field);
}

OptionTable& OptionTable::Paths(const std::string& name, std::vector<std::filesystem::path>* field,
                                const std::string& help) {
  List(name, WriteEach(field, [](const std::filesystem::path& path) { return path.string(); }),
       SetEach(field,
               [](const std::string& item, std::filesystem::path* value, std::string*) {
                 *value = item;
                 return true;
               }),
       "list of paths", help);
  return Sets(field);
}

OptionTable& OptionTable::Numbers(const std::string& name, std::vector<double>* field,
                                  Interval range, const std::string& unit,
                                  const std::string& help) {
  List(name, WriteEach(field, [](double value) { return OptionNumberText(value); }),
       SetEach(field,
               [range](const std::string& item, double* value, std::string* why) {
                 if (!ParseFinite(item, value)) {
                   *why = "expected finite numbers, got '" + item + "'";
                   return false;
                 }
                 return InRange(range, *value, why);
               }),
       "numbers in " + range.Text(), help);
  Option& option = options_.back();
  option.fields = {field};
  option.unit = unit;
  option.check = [field, range](std::string* why) {
    for (double value : *field) {
      if (!std::isfinite(value)) {
        *why = "must be finite numbers, got " + OptionNumberText(value);
        return false;
      }
      if (!InRange(range, value, why)) return false;
    }
    return true;
  };
  return *this;
}

OptionTable& OptionTable::Integers(const std::string& name, std::vector<int>* field, int min,
                                   int max, const std::string& unit, const std::string& help) {
  const Interval range = Interval::Closed(min, max);
  List(name, WriteEach(field, [](int value) { return std::to_string(value); }),
       SetEach(field,
               [range](const std::string& item, int* value, std::string* why) {
                 const char* end = item.data() + item.size();
                 const auto [last, error] = std::from_chars(item.data(), end, *value);
                 if (error != std::errc() || last != end) {
                   *why = "expected whole numbers, got '" + item + "'";
                   return false;
                 }
                 return InRange(range, *value, why);
               }),
       "whole numbers in " + range.Text(), help);
  Option& option = options_.back();
  option.fields = {field};
  option.unit = unit;
  option.check = [field, range](std::string* why) {
    for (int value : *field) {
      if (!InRange(range, value, why)) return false;
    }
    return true;
  };
  return *this;
}

OptionTable& OptionTable::Custom(const std::string& name, std::function<std::string()> get,
                                 std::function<bool(const std::string&, std::string*)> set,
                                 const std::string& values, const std::string& help) {
  Option& option = Add(name, Kind::kCustom, help);
  option.values = values;
  option.get = get;
  option.set = set;
  option.default_text = option.get();
  return *this;
}

OptionTable::Option& OptionTable::Last(const char* what) {
  if (options_.empty())
    throw std::invalid_argument("option table " + owner_ + ": " + what + " before any option");
  return options_.back();
}

OptionTable& OptionTable::Required() {
  Last("Required()").required = true;
  return *this;
}

OptionTable& OptionTable::Positional() {
  Last("Positional()").positional = true;
  return *this;
}

OptionTable& OptionTable::Sets(const void* field) {
  Last("Sets()").fields.push_back(field);
  return *this;
}

OptionTable& OptionTable::Repeated() {
  Option& option = Last("Repeated()");
  if (option.kind != Kind::kList)
    throw std::invalid_argument("option table " + owner_ + ": " + option.name + " is no list");
  option.repeated = true;
  option.set = [set_items = option.set_items](const std::string& text, std::string* why) {
    return set_items(text.empty() ? std::vector<std::string>() : std::vector<std::string>{text},
                     why);
  };
  return *this;
}

const OptionTable::Option* OptionTable::Find(const std::string& name) const {
  for (const Option& option : options_) {
    if (option.name == name) return &option;
  }
  return nullptr;
}

std::string OptionTable::FlagOf(const void* field) const {
  for (const Option& option : options_) {
    for (const void* set : option.fields) {
      if (set == field) return Written(option);
    }
  }
  throw std::logic_error("option table " + owner_ + ": no option sets the field named");
}

bool OptionTable::Check(std::string* why) const {
  for (const Option& option : options_) {
    if (option.required && option.get().empty()) {
      *why = Written(option) + " is required";
      return false;
    }
    std::string reason;
    if (!option.check(&reason)) {
      *why = Written(option) + ": " + reason;
      return false;
    }
  }
  return true;
}

std::vector<std::string> OptionTable::ChangedArguments() const {
  std::vector<std::string> arguments;
  for (const Option& option : options_) {
    const std::string value = option.get();
    if (value == option.default_text) continue;
    const std::string flag = "--" + option.name;
    if (option.kind == Kind::kFlag) {
      // A flag on by default is turned off as "--NAME=false".
      arguments.push_back(value == "true" ? flag : flag + "=false");
    } else if (option.kind == Kind::kList && (option.positional || option.repeated)) {
      for (const std::string& item : option.items()) {
        if (!option.positional) arguments.push_back(flag);
        arguments.push_back(item);
      }
    } else {
      if (!option.positional) arguments.push_back(flag);
      arguments.push_back(value);
    }
  }
  return arguments;
}

void OptionTable::Set(const std::string& name, const std::string& text) {
  const Option* option = Find(name);
  if (option == nullptr) {
    throw std::invalid_argument((owner_.empty() ? "" : owner_ + ": ") + "no option --" + name);
  }
  std::string why;
  if (!option->set(text, &why)) throw std::invalid_argument(Written(*option) + ": " + why);
}

std::string OptionTable::Markdown() const {
  std::string text = "| option | default | values | help |\n|---|---|---|---|\n";
  for (const Option& option : options_) {
    std::string values;
    switch (option.kind) {
      case Kind::kFlag:
        values = "flag";
        break;
      case Kind::kInteger:
        values = "whole number in " + option.range->Text();
        break;
      case Kind::kNumber:
        values = "number in " + option.range->Text();
        break;
      case Kind::kText:
        values = "text";
        break;
      case Kind::kPath:
        values = "path";
        break;
      case Kind::kChoice:
        values = ChoicesText(option.choices, " \\| ");
        break;
      case Kind::kList:
      case Kind::kCustom:
        values = option.values;
        break;
    }
    if (!option.unit.empty()) values += ", " + option.unit;
    if (option.required) values += ", required";
    std::string shown = option.default_text.empty() ? "" : "`" + option.default_text + "`";
    // A table cell holds no '|'.
    for (size_t at = shown.find('|'); at != std::string::npos; at = shown.find('|', at + 2))
      shown.replace(at, 1, "\\|");
    const std::string name = option.positional ? option.name : "--" + option.name;
    text += fmt::format("| `{}` | {} | {} | {} |\n", name, shown, values, option.help);
  }
  return text;
}

}  // namespace procam
