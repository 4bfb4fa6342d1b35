#pragma once
// Subcommands of the `ruffini` tool. Each Register* adds its subcommand to the app; the callback runs it.
#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdlib>
#include <optional>
#include <string>

namespace ruffini::cli {

void RegisterTwinCommands(CLI::App& app);
void RegisterDecodeCommands(CLI::App& app);
void RegisterBenchCommand(CLI::App& app);
void RegisterBenchServiceCommand(CLI::App& app);
void RegisterBenchAggregatorCommand(CLI::App& app);
void RegisterDemoCommand(CLI::App& app);
void RegisterResetCommand(CLI::App& app);
void RegisterSoakCommand(CLI::App& app);
void RegisterCoverageCommands(CLI::App& app);
void RegisterFieldHoursCommand(CLI::App& app);  // field-hours
void RegisterProbeCommand(CLI::App& app);      // grating-probe  // sensitivity, check-scene

// CLI::Range passes "nan" (every comparison with NaN is false): add this to a number option's checks to refuse
// NaN and infinities by name. It checks each value of a vector option.
inline CLI::Validator FiniteNumber() {
  return CLI::Validator(
      [](std::string& v) {
        char* end = nullptr;
        const double x = std::strtod(v.c_str(), &end);
        return end != v.c_str() && !std::isfinite(x) ? std::string("must be a finite number (got ") + v + ")" : std::string();
      },
      "FINITE");
}

// A model switch a command may override: "model" (unset: as the model file says), "on" or "off".
inline std::optional<bool> ModelOnOff(const std::string& v) {
  if (v == "on") return true;
  if (v == "off") return false;
  return std::nullopt;
}
inline constexpr const char* kFaintRefuseHelp =
    "Faint contact frames below the model's force (or 1 N) are no contact (the baseline stays frozen, its stale clock "
    "runs): as the model says (Preprocessing.faint_refuse_below_n), on or off (docs/decoders.md \"Faint frames\")";
inline constexpr const char* kReleaseRefuseHelp =
    "Where faint frames are refused: after a press, contact frames below this force are no contact while the press is "
    "recent (the cover's fading strain; docs/decoders.md \"Faint frames\"; 0: off)";
inline constexpr const char* kReleaseTauHelp = "With --release-refuse-n: how long a press counts as recent (its peak's decay, s)";

}  // namespace ruffini::cli
