// Always-on invariant checks. A failed MLFE_CHECK is a bug in mlfe, never bad input:
// it prints the condition and location and aborts. Bad input is reported with mlfe::Error
// (core/base/error.h) instead.
#pragma once
#include <cstdio>
#include <cstdlib>

#define MLFE_CHECK(cond)                                                                             \
  do {                                                                                               \
    if (!(cond)) {                                                                                   \
      std::fprintf(stderr, "mlfe: internal check failed: %s at %s:%d\n", #cond, __FILE__, __LINE__); \
      std::abort();                                                                                  \
    }                                                                                                \
  } while (0)

#define MLFE_CHECK_MSG(cond, msg)                                                                     \
  do {                                                                                                \
    if (!(cond)) {                                                                                    \
      std::fprintf(stderr, "mlfe: internal check failed: %s (%s) at %s:%d\n", #cond, (msg), __FILE__, \
                   __LINE__);                                                                         \
      std::abort();                                                                                   \
    }                                                                                                 \
  } while (0)
