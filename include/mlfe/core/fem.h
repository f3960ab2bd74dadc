// core/fem: The finite-element method on the hierarchy: the samples' lattice, P1 elements, element
// integrals and assembly, operators, CG with BPX or diagonal scaling, the least squares at the
// samples, error estimation and marking (L2 and surface-driven), the hierarchical basis, the
// adaptive loop (approximation.h) and resampling a hierarchy onto a grid.
//
// May include: core/base, core/mesh, core/field.
// (scripts/check_layering.py reads that line; docs/architecture.md draws the rooms.)
#pragma once
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/fem/bpx.h>
#include <mlfe/core/fem/element_integrals.h>
#include <mlfe/core/fem/fe_assembly.h>
#include <mlfe/core/fem/hierarchical_basis.h>
#include <mlfe/core/fem/hierarchy_resample.h>
#include <mlfe/core/fem/linear_operator.h>
#include <mlfe/core/fem/marking.h>
#include <mlfe/core/fem/p1_element.h>
#include <mlfe/core/fem/sample_lattice.h>
#include <mlfe/core/fem/sampled_least_squares.h>
#include <mlfe/core/fem/surface_estimator.h>
