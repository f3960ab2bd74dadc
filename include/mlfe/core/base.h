// core/base: What every room stands on: CHECK for bugs, the one exception type for bad input (mlfe::Error,
// with UsageError for options), default-initialized allocation, huge-page hints, the arithmetic of
// 3-vectors held as arrays (vec.h), and, inside core/base/, counting sort and Morton order.
//
// May include: nothing of the project.
// (scripts/check_layering.py reads that line; docs/architecture.md draws the rooms.)
#pragma once
#include <mlfe/core/base/check.h>
#include <mlfe/core/base/default_init.h>
#include <mlfe/core/base/error.h>
#include <mlfe/core/base/huge_pages.h>
#include <mlfe/core/base/usage_error.h>
#include <mlfe/core/base/vec.h>
