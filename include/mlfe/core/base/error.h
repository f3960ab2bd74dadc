// The one documented error type for bad input. Readers, writers and the core throw
// mlfe::Error with a one-line message; the command line catches it at the top level,
// prints "mlfe: <message>" and exits with status 2.
#pragma once
#include <stdexcept>
#include <string>

namespace mlfe {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

}  // namespace mlfe
