#pragma once
// Strict YAML reading for configuration files: every key must be known, every number in range, and an
// error names file:line:col, the full key path, the value seen and what was expected, e.g.
//   config/patches/forearm.yaml:12:3: 'gratings[4].wavelength_nm' (1512) must lie inside 1510..1590
// yaml-cpp does the parsing; this wrapper only adds the bookkeeping for good messages.
#include <yaml-cpp/yaml.h>

#include <functional>
#include <optional>
#include <initializer_list>
#include <set>
#include <string>
#include <string_view>
#include <vector>

namespace ruffini {

class YamlReader {
 public:
  // Parses text (throws InputError with the parser's position on a syntax error).
  static YamlReader Parse(const std::string& text, const std::string& source);
  static YamlReader LoadFile(const std::string& path);

  YamlReader(YAML::Node node, std::string source, std::string path);

  [[nodiscard]] bool Has(const std::string& key) const;
  [[nodiscard]] double Number(const std::string& key, double min, double max);
  [[nodiscard]] double NumberOr(const std::string& key, double fallback, double min, double max);
  [[nodiscard]] long Integer(const std::string& key, long min, long max);
  [[nodiscard]] long IntegerOr(const std::string& key, long fallback, long min, long max);
  [[nodiscard]] bool BoolOr(const std::string& key, bool fallback);
  [[nodiscard]] std::string String(const std::string& key);
  [[nodiscard]] std::string StringOr(const std::string& key, const std::string& fallback);
  // One of `choices`; the message lists them.
  [[nodiscard]] std::string Choice(const std::string& key, const std::vector<std::string>& choices);
  [[nodiscard]] std::string ChoiceOr(const std::string& key, const std::string& fallback,
                                     const std::vector<std::string>& choices);
  [[nodiscard]] YamlReader Map(const std::string& key);
  [[nodiscard]] std::optional<YamlReader> MapOr(const std::string& key);
  [[nodiscard]] std::vector<YamlReader> Sequence(const std::string& key);
  // A sequence of numbers.
  [[nodiscard]] std::vector<double> Numbers(const std::string& key, double min, double max);

  // Throws naming the first key that was never read: unknown keys are errors, not silently ignored.
  void Finish() const;
  // Counts these keys as known without reading them, so Finish() accepts them: for a file whose parts are
  // parsed by different code (a scene's root reader knows every patch key; the robot part reads `mount`).
  void Allow(std::initializer_list<std::string_view> keys);

  // Throws InputError "<file:line:col of key>: '<path.key>' (<value>) <what>".
  [[noreturn]] void Fail(const std::string& key, const std::string& what) const;
  // Same, at this node itself.
  [[noreturn]] void FailHere(const std::string& what) const;

  [[nodiscard]] const std::string& path() const { return path_; }
  [[nodiscard]] const std::string& source() const { return source_; }
  [[nodiscard]] std::string Where(const std::string& key) const;  // "file:line:col"

 private:
  [[nodiscard]] YAML::Node Required(const std::string& key, const char* kind);
  [[nodiscard]] std::string KeyPath(const std::string& key) const;

  YAML::Node node_;
  std::string source_;
  std::string path_;
  std::set<std::string> read_;
};

// Formats a number the way messages show it (shortest round-trip form).
std::string FormatNumber(double v);

}  // namespace ruffini
