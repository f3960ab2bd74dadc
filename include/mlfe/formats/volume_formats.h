// What the table of volume formats (formats/volume_formats.cpp) tells the rest of mlfe about
// file names. read_volume and write_volume ask the table itself.
#pragma once
#include <string>
#include <vector>

namespace mlfe {

/// The file name endings of scans, lower case with their dot (".nii.gz" whole), none the end of
/// another: those of the volume files that are a scan by themselves (".nrrd", ".nii.gz", ...;
/// not the halves of a .hdr/.img pair, raw data that needs a sidecar, or 2D images) and of the
/// tetrahedral meshes (".vtu", ".msh"). mlfe.batch takes the files of a folder with these
/// endings (in any case) for its scans; find_label_table drops them for a volume's stem.
const std::vector<std::string>& scan_extensions();

}  // namespace mlfe
