// A bad option value (out of range, not finite, malformed) as opposed to bad input data: still
// an mlfe::Error for library and Python callers, but the command line exits with its usage
// status (1; 2 for compare) for it, as for every other usage error.
#pragma once
#include <mlfe/core/base/error.h>

namespace mlfe {

class UsageError : public Error {
 public:
  using Error::Error;
};

}  // namespace mlfe
