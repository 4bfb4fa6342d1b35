#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include "ruffini/error.h"
#include "ruffini/yaml_reader.h"

namespace ruffini {

std::string FormatNumber(double v) {
  char buf[64];
  auto res = std::to_chars(buf, buf + sizeof buf, v);
  return {buf, res.ptr};
}

namespace {
std::string MarkString(const std::string& source, const YAML::Mark& m) {
  if (m.line < 0) return source;
  return source + ":" + std::to_string(m.line + 1) + ":" + std::to_string(m.column + 1);
}
std::string RangeText(double min, double max) { return FormatNumber(min) + ".." + FormatNumber(max); }
}  // namespace

YamlReader YamlReader::Parse(const std::string& text, const std::string& source) {
  try {
    YAML::Node root = YAML::Load(text);
    if (!root.IsMap()) throw InputError(source + ": expected a YAML mapping at the top level");
    return YamlReader(root, source, "");
  } catch (const YAML::Exception& e) {
    throw InputError(MarkString(source, e.mark) + ": YAML syntax error: " + e.msg);
  }
}

YamlReader YamlReader::LoadFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path + ": cannot open file");
  std::stringstream ss;
  ss << in.rdbuf();
  return Parse(ss.str(), path);
}

YamlReader::YamlReader(YAML::Node node, std::string source, std::string path)
    : node_(std::move(node)), source_(std::move(source)), path_(std::move(path)) {
  if (!node_.IsMap()) return;
  std::set<std::string> seen;
  for (auto it = node_.begin(); it != node_.end(); ++it) {
    if (!it->first.IsScalar()) {
      throw InputError(MarkString(source_, it->first.Mark()) + ": a key in '" + (path_.empty() ? "(top)" : path_) +
                       "' is not a plain name");
    }
    if (!seen.insert(it->first.Scalar()).second) {
      // yaml-cpp would keep one of two equal keys; a config that says a thing twice is an error.
      throw InputError(MarkString(source_, it->first.Mark()) + ": '" + KeyPath(it->first.Scalar()) + "' appears twice");
    }
  }
}

std::string YamlReader::KeyPath(const std::string& key) const {
  if (path_.empty()) return key;
  if (!key.empty() && key[0] == '[') return path_ + key;
  return path_ + "." + key;
}

std::string YamlReader::Where(const std::string& key) const {
  if (!key.empty() && node_.IsMap()) {
    for (auto it = node_.begin(); it != node_.end(); ++it) {
      if (it->first.IsScalar() && it->first.Scalar() == key) return MarkString(source_, it->first.Mark());
    }
  }
  return MarkString(source_, node_.Mark());
}

void YamlReader::Fail(const std::string& key, const std::string& what) const {
  std::string value;
  if (node_.IsMap() && node_[key] && node_[key].IsScalar()) value = " (" + node_[key].Scalar() + ")";
  throw InputError(Where(key) + ": '" + KeyPath(key) + "'" + value + " " + what);
}

void YamlReader::FailHere(const std::string& what) const {
  throw InputError(MarkString(source_, node_.Mark()) + ": '" + path_ + "' " + what);
}

bool YamlReader::Has(const std::string& key) const { return node_.IsMap() && node_[key]; }

YAML::Node YamlReader::Required(const std::string& key, const char* kind) {
  if (!node_.IsMap()) FailHere("must be a mapping");
  YAML::Node n = node_[key];
  if (!n) {
    throw InputError(MarkString(source_, node_.Mark()) + ": '" + KeyPath(key) + "' is missing (" + kind +
                     " expected)");
  }
  read_.insert(key);
  return n;
}

double YamlReader::Number(const std::string& key, double min, double max) {
  YAML::Node n = Required(key, "a number");
  double v = 0.0;
  if (!n.IsScalar() || !YAML::convert<double>::decode(n, v) || !std::isfinite(v)) {
    Fail(key, "must be a finite number");
  }
  if (v < min || v > max) Fail(key, "must lie inside " + RangeText(min, max));
  return v;
}

double YamlReader::NumberOr(const std::string& key, double fallback, double min, double max) {
  if (!Has(key)) return fallback;
  return Number(key, min, max);
}

long YamlReader::Integer(const std::string& key, long min, long max) {
  YAML::Node n = Required(key, "an integer");
  long v = 0;
  if (!n.IsScalar() || !YAML::convert<long>::decode(n, v)) Fail(key, "must be an integer");
  if (v < min || v > max) Fail(key, "must lie inside " + std::to_string(min) + ".." + std::to_string(max));
  return v;
}

long YamlReader::IntegerOr(const std::string& key, long fallback, long min, long max) {
  if (!Has(key)) return fallback;
  return Integer(key, min, max);
}

bool YamlReader::BoolOr(const std::string& key, bool fallback) {
  if (!Has(key)) return fallback;
  YAML::Node n = Required(key, "true or false");
  bool v = false;
  if (!n.IsScalar() || !YAML::convert<bool>::decode(n, v)) Fail(key, "must be true or false");
  return v;
}

std::string YamlReader::String(const std::string& key) {
  YAML::Node n = Required(key, "a string");
  if (!n.IsScalar() || n.Scalar().empty()) Fail(key, "must be a non-empty string");
  return n.Scalar();
}

std::string YamlReader::StringOr(const std::string& key, const std::string& fallback) {
  if (!Has(key)) return fallback;
  return String(key);
}

std::string YamlReader::Choice(const std::string& key, const std::vector<std::string>& choices) {
  std::string v = String(key);
  for (const auto& c : choices) {
    if (c == v) return v;
  }
  std::string list;
  for (const auto& c : choices) list += (list.empty() ? "" : ", ") + c;
  Fail(key, "must be one of: " + list);
}

std::string YamlReader::ChoiceOr(const std::string& key, const std::string& fallback,
                                 const std::vector<std::string>& choices) {
  if (!Has(key)) return fallback;
  return Choice(key, choices);
}

YamlReader YamlReader::Map(const std::string& key) {
  YAML::Node n = Required(key, "a mapping");
  if (!n.IsMap()) Fail(key, "must be a mapping");
  return YamlReader(n, source_, KeyPath(key));
}

std::optional<YamlReader> YamlReader::MapOr(const std::string& key) {
  if (!Has(key)) return std::nullopt;
  return Map(key);
}

std::vector<YamlReader> YamlReader::Sequence(const std::string& key) {
  YAML::Node n = Required(key, "a sequence");
  if (!n.IsSequence()) Fail(key, "must be a sequence");
  std::vector<YamlReader> out;
  for (std::size_t i = 0; i < n.size(); ++i) {
    out.emplace_back(n[i], source_, KeyPath(key) + "[" + std::to_string(i) + "]");
  }
  return out;
}

std::vector<double> YamlReader::Numbers(const std::string& key, double min, double max) {
  YAML::Node n = Required(key, "a sequence of numbers");
  if (!n.IsSequence()) Fail(key, "must be a sequence of numbers");
  std::vector<double> out;
  for (std::size_t i = 0; i < n.size(); ++i) {
    double v = 0.0;
    if (!n[i].IsScalar() || !YAML::convert<double>::decode(n[i], v) || !std::isfinite(v) || v < min ||
        v > max) {
      throw InputError(MarkString(source_, n[i].Mark()) + ": '" + KeyPath(key) + "[" + std::to_string(i) +
                       "]' (" + (n[i].IsScalar() ? n[i].Scalar() : std::string("?")) +
                       ") must be a number inside " + RangeText(min, max));
    }
    out.push_back(v);
  }
  return out;
}

void YamlReader::Allow(std::initializer_list<std::string_view> keys) {
  for (std::string_view k : keys) read_.emplace(k);
}

void YamlReader::Finish() const {
  if (!node_.IsMap()) return;
  for (auto it = node_.begin(); it != node_.end(); ++it) {
    const std::string& key = it->first.Scalar();
    if (!read_.count(key)) {
      throw InputError(MarkString(source_, it->first.Mark()) + ": '" + KeyPath(key) +
                       "' is not a known key here");
    }
  }
}

}  // namespace ruffini
