// core/mesh: The red-green tetrahedral (triangular in 2D) hierarchy: elements, vertices and edges with
// typed ids, refinement (Bank 2D, Bey 3D) and its closure, the edge map, simplex shape measures.
// It knows no values: fields, integrals and solvers live above it.
//
// May include: core/base.
// (scripts/check_layering.py reads that line; docs/architecture.md draws the rooms.)
#pragma once
#include <mlfe/core/mesh/edge_map.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/core/mesh/ids.h>
#include <mlfe/core/mesh/mesh_quality.h>
