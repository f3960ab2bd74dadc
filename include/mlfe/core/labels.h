// core/labels: Label maps: the interface complex of all structures on the lattice, its smoothing within the
// voxel bound and one closed, manifold mesh per structure with shared interfaces.
//
// May include: core/base, core/mesh, core/field, core/surface, core/simplify.
// (scripts/check_layering.py reads that line; docs/architecture.md draws the rooms.)
#pragma once
#include <mlfe/core/labels/label_surface.h>
