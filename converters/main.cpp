// mlfe: multilevel finite elements for volume data (Grosso, Lürig & Ertl, IEEE Vis 1997).
// Exit status: 0 success, 1 usage error, 2 bad input (one line on stderr naming the file).
// `compare` follows diff(1) instead: 0 equal, 1 different, 2 bad input or usage error.
#include <mlfe/core/error.h>
#include <mlfe/version.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cstdio>
#include <exception>
#include <memory>
#include <new>

#include "converters/commands.h"

namespace mlfe::cli {
int& thread_option() {
  static int threads = 0;
  return threads;
}
int& command_exit_status() {
  static int status = 0;
  return status;
}
}  // namespace mlfe::cli

int main(int argc, char** argv) {
  CLI::App app{
      "mlfe: adaptive multilevel finite-element approximation of volume data "
      "(hierarchies, iso-surfaces, glTF/Draco assets)"};
  app.set_version_flag("--version", std::string("mlfe ") + MLFE_VERSION);
  app.add_option("--threads", mlfe::cli::thread_option(),
                 "worker threads (0: all cores); output does not depend on it")
      ->check(CLI::NonNegativeNumber);
  app.require_subcommand(1);
  auto& registry = mlfe::cli::command_registry();
  std::stable_sort(registry.begin(), registry.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& entry : registry) entry.second(app);

  std::unique_ptr<tbb::global_control> threads;
  app.parse_complete_callback([&] {
    if (mlfe::cli::thread_option() > 0)
      threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                      mlfe::cli::thread_option());
  });
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // CLI11 prints the message (or --help / --version) and returns its own error numbers
    // (105, 106, ...); the documented contract is 1 for every usage error, except for compare,
    // whose 1 means "different".
    const int usage_status = app.got_subcommand("compare") ? 2 : 1;
    return app.exit(e) == 0 ? 0 : usage_status;
  } catch (const mlfe::Error& e) {
    std::fprintf(stderr, "mlfe: %s\n", e.what());
    return 2;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "mlfe: out of memory\n");
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "mlfe: %s\n", e.what());
    return 2;
  }
  return mlfe::cli::command_exit_status();
}
