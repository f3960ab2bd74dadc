// mlfe: multilevel finite elements for volume data (Grosso, Lürig & Ertl, IEEE Vis 1997).
// The umbrella header: the pipeline (volume → adaptive hierarchy → assets), its core (the
// red-green hierarchy, the adaptive L2 approximation, iso-surfaces, simplification, ray casting)
// and the formats. Bad input anywhere throws mlfe::Error (mlfe/core/error.h).
#pragma once

#include <mlfe/core/base/error.h>
#include <mlfe/core/fem/approximation.h>
#include <mlfe/core/fem/hierarchical_basis.h>
#include <mlfe/core/field/field.h>
#include <mlfe/core/field/scalar_grid.h>
#include <mlfe/core/mesh/hierarchy.h>
#include <mlfe/core/render/transfer_function.h>
#include <mlfe/core/render/volume_render.h>
#include <mlfe/core/simplify/surface_simplification.h>
#include <mlfe/core/surface/iso_surface.h>
#include <mlfe/core/surface/mesh_distance.h>
#include <mlfe/core/surface/triangle_mesh.h>
#include <mlfe/formats/draco_io.h>
#include <mlfe/formats/exr_writer.h>
#include <mlfe/formats/gltf_writer.h>
#include <mlfe/formats/hierarchy_io.h>
#include <mlfe/formats/volume_reader.h>
#include <mlfe/pipeline.h>
#include <mlfe/pipeline/compare.h>
#include <mlfe/version.h>
