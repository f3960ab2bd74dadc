// core/simplify: Every simplifier of triangle surfaces behind one interface (simplifier.h: the kind,
// the options, simplify()): the error-bounded Simplifier, the fast quadric path (meshoptimizer) and
// the decimation of interface complexes (core/labels' label interfaces); and iso-surfaces extracted
// and simplified in bricks of the samples' lattice (bricked_iso_surface.h), read window by window.
//
// May include: core/base, core/mesh, core/field, core/surface.
// (scripts/check_layering.py reads that line; docs/architecture.md draws the rooms.)
#pragma once
#include <mlfe/core/simplify/simplifier.h>
