// mlfe: multilevel finite elements for volume data (Grosso, Lürig & Ertl, IEEE Vis 1997).
// Exit status: 0 success, 1 usage error, 2 bad input (one line on stderr naming the file), 130
// interrupted (Ctrl-C; no output written).
// `compare` follows diff(1) instead: 0 equal, 1 different, 2 bad input or usage error.
#include <fmt/format.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/formats/atomic_file.h>
#include <mlfe/version.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include "converters/cli/commands.h"
#include "converters/cli/pipeline_options.h"

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

namespace {

// One rule for every number on the command line: "nan" and "inf" parse as doubles, and no
// option means anything by them (a NaN azimuth crashed the renderer), so they are usage errors.
void require_finite_numbers(CLI::App& app) {
  const CLI::Validator finite(
      [](std::string& text) -> std::string {
        char* end = nullptr;
        const double v = std::strtod(text.c_str(), &end);
        if (end != text.c_str() && *end == '\0' && !std::isfinite(v))
          return "expected a finite number, got '" + text + "'";
        return {};
      },
      "FINITE");
  for (CLI::App* cmd : app.get_subcommands([](CLI::App*) { return true; }))
    for (CLI::Option* opt : cmd->get_options([](CLI::Option*) { return true; }))
      if (opt->get_type_name().rfind("FLOAT", 0) == 0) opt->check(finite);
}

// The values an option of the library's table takes, in its help ("INT:0..40"); the library
// checks them when the command calls it.
void describe_values(CLI::App& app) {
  std::vector<CLI::App*> apps = app.get_subcommands([](CLI::App*) { return true; });
  apps.push_back(&app);
  for (CLI::App* cmd : apps)
    for (CLI::Option* opt : cmd->get_options([](CLI::Option*) { return true; }))
      for (const auto& name : opt->get_lnames())
        if (const auto* spec = mlfe::pipeline::option_by_flag("--" + name); spec && !spec->values().empty())
          opt->type_name(opt->get_type_name() + ":" + spec->values());
}

std::size_t edit_distance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diag = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

std::string nearest(const std::string& word, const std::vector<std::string>& names) {
  std::string best;
  std::size_t best_distance = std::max<std::size_t>(2, word.size() / 3) + 1;
  for (const auto& n : names) {
    const std::size_t d = edit_distance(word, n);
    if (d < best_distance) {
      best_distance = d;
      best = n;
    }
  }
  return best;
}

// An error is one line of about 200 characters on stderr: a file name with a newline split it
// over two lines, and a 10 kB number from a label table was echoed whole. Control characters
// are written as escapes (\n, \t, \xHH); a long message keeps its start, which names the file,
// and its end, which most often says what is wrong with it.
std::string escaped(const std::string& text) {
  std::string out;
  for (const char c : text) {
    const auto u = static_cast<unsigned char>(c);
    if (c == '\n')
      out += "\\n";
    else if (c == '\r')
      out += "\\r";
    else if (c == '\t')
      out += "\\t";
    else if (u < 0x20 || u == 0x7f)
      out += fmt::format("\\x{:02x}", u);
    else
      out += c;
  }
  return out;
}

std::string error_line(const std::string& message) {
  constexpr std::size_t kHead = 150, kTail = 50;
  if (message.size() <= kHead + kTail) return "mlfe: " + escaped(message);
  // The cuts fall between UTF-8 characters, not inside one.
  const auto continuation = [&](std::size_t i) {
    return (static_cast<unsigned char>(message[i]) & 0xC0) == 0x80;
  };
  std::size_t head = kHead, tail = message.size() - kTail;
  while (head > 0 && continuation(head)) --head;
  while (tail < message.size() && continuation(tail)) ++tail;
  return "mlfe: " + escaped(message.substr(0, head)) + " [...] " + escaped(message.substr(tail));
}

// CLI11 names what it did not understand but not what was meant: the nearest subcommand for
// an unknown first word, the nearest long option of the command (or a global one) otherwise, as
// the one line to print instead of CLI11's message; "" when nothing is near.
std::string suggestion(CLI::App& app, int argc, char** argv) {
  std::vector<std::string> commands;
  for (const CLI::App* cmd : app.get_subcommands([](CLI::App*) { return true; }))
    commands.push_back(cmd->get_name());
  const std::vector<CLI::App*> used = app.get_subcommands();
  std::vector<std::string> options;
  const auto add_options = [&](CLI::App* a) {
    for (const CLI::Option* opt : a->get_options())
      for (const auto& n : opt->get_lnames()) options.push_back("--" + n);
  };
  add_options(&app);
  if (!used.empty()) add_options(used.front());
  const bool command_seen = !used.empty();
  for (int i = 1; i < argc; ++i) {
    std::string word = argv[i];
    if (word.rfind("--", 0) == 0) {
      const std::string name = word.substr(0, word.find('='));
      if (std::find(options.begin(), options.end(), name) != options.end()) continue;
      const std::string s = nearest(name, options);
      if (!s.empty()) return "mlfe: " + escaped(name) + ": unknown option; did you mean " + s + "?";
    } else if (!command_seen && !word.empty() && word[0] != '-') {
      if (std::find(commands.begin(), commands.end(), word) != commands.end()) return "";
      const std::string s = nearest(word, commands);
      return s.empty() ? "" : "mlfe: " + escaped(word) + ": unknown command; did you mean " + s + "?";
    }
  }
  return "";
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "mlfe: adaptive multilevel finite-element approximation of volume data "
      "(hierarchies, iso-surfaces, glTF/Draco assets)"};
  app.set_version_flag("--version", std::string("mlfe ") + MLFE_VERSION);
  app.add_option("--threads", mlfe::cli::thread_option(),
                 "worker threads (0: all cores); output does not depend on it");
  app.require_subcommand(1);
  // Global options (--threads) are accepted after the subcommand too.
  app.fallthrough();
  auto& registry = mlfe::cli::command_registry();
  std::stable_sort(registry.begin(), registry.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  for (const auto& entry : registry) entry.second(app);
  describe_values(app);  // before the finite check joins the type names
  require_finite_numbers(app);

  std::unique_ptr<tbb::global_control> threads;
  app.parse_complete_callback([&] {
    mlfe::pipeline::check_option("threads", mlfe::cli::thread_option());
    if (mlfe::cli::thread_option() > 0)
      threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism,
                                                      mlfe::cli::thread_option());
  });
  try {
    // Every output of the command appears at the end, together, or none does.
    mlfe::OutputBatch outputs;
    app.parse(argc, argv);
    outputs.commit();
  } catch (const CLI::ParseError& e) {
    // CLI11 prints the message (or --help / --version) and returns its own error numbers
    // (105, 106, ...); the documented contract is 1 for every usage error, except for compare,
    // whose 1 means "different".
    const int usage_status = app.got_subcommand("compare") ? 2 : 1;
    if (e.get_exit_code() == 0) return app.exit(e);  // --help, --version
    // A misspelt word is the one line "mlfe: --simplfy: unknown option; did you mean --simplify?".
    const std::string hint = suggestion(app, argc, argv);
    if (hint.empty())
      app.exit(e);
    else
      mlfe::cli::status_line(hint);
    return usage_status;
  } catch (const mlfe::pipeline::Cancelled&) {  // Ctrl-C (progress_display): nothing written
    mlfe::cli::status_line("mlfe: interrupted");
    return 130;
  } catch (const mlfe::UsageError& e) {
    mlfe::cli::status_line(error_line(mlfe::pipeline::message(e, mlfe::pipeline::Spelling::kCommandLine)));
    return app.got_subcommand("compare") ? 2 : 1;
  } catch (const mlfe::Error& e) {
    mlfe::cli::status_line(error_line(mlfe::pipeline::message(e, mlfe::pipeline::Spelling::kCommandLine)));
    return 2;
  } catch (const std::bad_alloc&) {
    mlfe::cli::status_line("mlfe: out of memory");
    return 2;
  } catch (const std::exception& e) {
    mlfe::cli::status_line(error_line(e.what()));
    return 2;
  }
  return mlfe::cli::command_exit_status();
}
