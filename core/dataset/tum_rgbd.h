// The TUM RGB-D benchmark layout (Sturm et al. 2012) as a dataset (docs/dataset-format.md, "TUM
// RGB-D"): `rgb.txt` and `depth.txt` (`t_s path`, each at its own sensor's times), 16-bit depth
// PNGs in 1/5000 m, `groundtruth.txt` (TUM, world_from_cam), and the association of colour and
// depth frames by nearest time stamp.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <vector>

#include "core/dataset/dataset.h"

namespace evloc {

// True when `root` is a folder with rgb.txt and without images.txt.
bool IsTumRgbdFolder(const std::filesystem::path& root);

// Reads a TUM RGB-D folder: images from rgb.txt, depth from depth.txt (both kept at their own
// times; pair them with AssociateByTime), ground truth from groundtruth.txt when present,
// layout kTumRgbd and depth_units_per_metre 5000. The camera comes from calib.yaml, else from
// calib.txt (`fx fy cx cy k1 k2 p1 p2 k3`, TUM's d0..d4 order) sized as the first colour image:
// the benchmark ships its intrinsics only in its documentation. Throws IoError when a listed
// file is missing, ParseError naming the file and line for a malformed list,
// InvalidArgumentError when there is no calibration (the message gives the freiburg values).
Dataset ReadTumRgbdDataset(const std::filesystem::path& root);

// One associated pair: an index into the first list and one into the second.
struct TimeAssociation {
  // Index into the first list.
  size_t first = 0;
  // Index into the second list.
  size_t second = 0;
};

// Associates two time-ordered lists as the TUM tools' associate.py does: every pair closer than
// or equal to `max_difference_ns` is a candidate; candidates are taken greedily from the closest
// pair on, each entry used at most once. Returned in the order of the first list. Throws
// InvalidArgumentError when max_difference_ns is negative.
std::vector<TimeAssociation> AssociateByTime(const std::vector<TimedFile>& first,
                                             const std::vector<TimedFile>& second,
                                             int64_t max_difference_ns);

}  // namespace evloc
