// core/field: Functions to approximate: voxel grids (ScalarGrid), the Field interface over them with its
// min/max pyramid, fields of unstructured tetrahedral meshes, and the noise estimate of a scan.
//
// May include: core/base, core/mesh.
// (scripts/check_layering.py reads that line; docs/architecture.md draws the rooms.)
#pragma once
#include <mlfe/core/field/field.h>
#include <mlfe/core/field/minmax_pyramid.h>
#include <mlfe/core/field/noise_estimate.h>
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/field/tet_mesh_field.h>
