#include "base/option_table.h"

#include <fmt/format.h>

#include <charconv>
#include <cmath>
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

bool InRange(const OptionTable::Interval& range, double value, std::string* why) {
  if (range.Contains(value)) return true;
  *why = fmt::format("must be in {}, got {}", range.Text(), OptionNumberText(value));
  return false;
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

}  // namespace

bool OptionTable::Interval::Contains(double value) const {
  return (min_open ? value > min : value >= min) && (max_open ? value < max : value <= max);
}

std::string OptionTable::Interval::Text() const {
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
  option.unit = unit;
  option.range = range;
  option.get = [field] { return OptionNumberText(*field); };
  option.set = [field, range](const std::string& text, std::string* why) {
    double value = 0.0;
    if (!ParseFinite(text, &value)) {
      *why = "expected a finite number, got '" + text + "'";
      return false;
    }
    if (!InRange(range, value, why)) return false;
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

const OptionTable::Option* OptionTable::Find(const std::string& name) const {
  for (const Option& option : options_) {
    if (option.name == name) return &option;
  }
  return nullptr;
}

bool OptionTable::Check(std::string* why) const {
  for (const Option& option : options_) {
    std::string reason;
    if (!option.check(&reason)) {
      *why = "--" + option.name + ": " + reason;
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
    if (option.kind == Kind::kFlag) {
      // A flag on by default is turned off as "--NAME=false".
      arguments.push_back(value == "true" ? "--" + option.name : "--" + option.name + "=false");
    } else {
      arguments.push_back("--" + option.name);
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
  if (!option->set(text, &why)) throw std::invalid_argument("--" + name + ": " + why);
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
    }
    if (!option.unit.empty()) values += ", " + option.unit;
    const std::string shown = option.default_text.empty() ? "" : "`" + option.default_text + "`";
    text += fmt::format("| `--{}` | {} | {} | {} |\n", option.name, shown, values, option.help);
  }
  return text;
}

}  // namespace procam
