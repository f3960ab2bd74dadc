// The files a read opens besides the one it is given, found by the readers themselves, so that
// a call can refuse an output that would replace one of them (issue 43: `--report v.raw.json`
// overwrote the sidecar of v.raw). Like read_volume, it sits above the readers.
#pragma once
#include <string>
#include <vector>

namespace mlfe {
/// Every file a read of `path` opens: `path` first, then the files beside it that its reader
/// reads too, as the reader finds them: a raw volume's .json sidecar, a detached NRRD's data
/// files, the other half of a NIfTI/Analyze .hdr/.img pair, a MetaImage's ElementDataFile, the
/// buffer files of a .gltf/.glb, the .lut beside an MRIcron .txt label table. Only `path` when nothing exists
/// there yet (the read will say so). The outputs of a call are checked against these before any work, so that
/// no output replaces a file the call reads. Throws mlfe::Error as the reader would for a header it cannot
/// read (a FIFO, a bad data file name).
std::vector<std::string> input_files(const std::string& path);

}  // namespace mlfe
