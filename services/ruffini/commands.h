#pragma once
// Subcommands of the `ruffini` tool. Each Register* adds its subcommand to the app; the callback runs it.
#include <CLI/CLI.hpp>

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

}  // namespace ruffini::cli
