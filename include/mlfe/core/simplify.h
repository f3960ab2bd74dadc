// core/simplify: Every simplifier of triangle surfaces behind one interface: the error-bounded Simplifier,
// the fast quadric path (meshoptimizer) and the decimation of label interface complexes.
//
// May include: core/base, core/mesh, core/surface.
// (scripts/check_layering.py reads that line; docs/architecture.md draws the rooms.)
#pragma once
#include <mlfe/core/simplify/surface_simplification.h>
