// core/surface: Triangle surfaces: the TriangleMesh type and its merge, iso-surfaces by marching tetrahedra
// on the hierarchy or on the samples' lattice with the paper's normals, surface fitting, and
// distances between meshes.
//
// May include: core/base, core/mesh, core/field, core/fem.
// (scripts/check_layering.py reads that line; docs/architecture.md draws the rooms.)
#pragma once
#include <mlfe/core/surface/iso_surface.h>
#include <mlfe/core/surface/mesh_distance.h>
#include <mlfe/core/surface/surface_fitting.h>
#include <mlfe/core/surface/triangle_mesh.h>
