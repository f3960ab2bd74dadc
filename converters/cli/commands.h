// Each subcommand of the mlfe command line lives in its own cmd_*.cpp and registers itself
// with MLFE_REGISTER_COMMAND(order, function). Commands report bad input by throwing
// mlfe::Error; main() turns it into one line on stderr and exit status 2.
#pragma once
#include <CLI/CLI.hpp>
#include <functional>
#include <utility>
#include <vector>

namespace mlfe::cli {

using CommandAdder = void (*)(CLI::App& app);

inline std::vector<std::pair<int, CommandAdder>>& command_registry() {
  static std::vector<std::pair<int, CommandAdder>> registry;
  return registry;
}

struct CommandRegistrar {
  CommandRegistrar(int order, CommandAdder adder) { command_registry().emplace_back(order, adder); }
};

/// Number of worker threads requested with --threads (0: all cores).
int& thread_option();

/// Exit status a command asks for when it completes without an error (0 unless set; `compare`
/// sets 1 for "different").
int& command_exit_status();

}  // namespace mlfe::cli

#define MLFE_CLI_CONCAT2(a, b) a##b
#define MLFE_CLI_CONCAT(a, b) MLFE_CLI_CONCAT2(a, b)
#define MLFE_REGISTER_COMMAND(order, fn) \
  static ::mlfe::cli::CommandRegistrar MLFE_CLI_CONCAT(mlfe_cmd_registrar_, __LINE__)(order, fn)
