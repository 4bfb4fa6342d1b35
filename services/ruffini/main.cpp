// ruffini: the command-line tool. Subcommands live in cmd_*.cpp; this file only wires them and maps
// errors to exit codes: 0 ok, 1 bad input (the message says what), 2 usage.
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <exception>

#include "commands.h"
#include "ruffini/error.h"

int main(int argc, char** argv) {
  spdlog::set_default_logger(spdlog::stderr_color_mt("ruffini"));  // stdout carries results only
  CLI::App app{"ruffini: optical robot skin tools (twin, datasets, reports)"};
  app.require_subcommand(1);
  app.set_help_all_flag("--help-all", "Show help for every subcommand");
  ruffini::cli::RegisterTwinCommands(app);
  ruffini::cli::RegisterDecodeCommands(app);
  ruffini::cli::RegisterBenchCommand(app);
  ruffini::cli::RegisterBenchServiceCommand(app);
  ruffini::cli::RegisterBenchAggregatorCommand(app);
  ruffini::cli::RegisterDemoCommand(app);
  ruffini::cli::RegisterResetCommand(app);
  ruffini::cli::RegisterSoakCommand(app);
  ruffini::cli::RegisterCoverageCommands(app);
  ruffini::cli::RegisterProbeCommand(app);
  ruffini::cli::RegisterFieldHoursCommand(app);
  try {
    app.parse(argc, argv);
  } catch (const CLI::RuntimeError& e) {
    return e.get_exit_code();  // a command's own non-zero status (demo: 3 = an expectation failed)
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  } catch (const ruffini::InputError& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
