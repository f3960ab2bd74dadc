// core/render: Volume ray casting from cell face to cell face through the tetrahedral hierarchy (trapezoid
// rule, early termination, a stable exit near edges) and the transfer functions it applies.
//
// May include: core/base, core/mesh, core/field, core/fem.
// (scripts/check_layering.py reads that line; docs/architecture.md draws the rooms.)
#pragma once
#include <mlfe/core/render/transfer_function.h>
#include <mlfe/core/render/volume_render.h>
