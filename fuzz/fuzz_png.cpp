// A camera frame as `mcms track` reads it (tracking/sequence.h LoadFrameImages): the PNG
// header check, then OpenCV's decoder. Problems are reported per frame, not thrown, so
// the outcome is an image or a reason; an image must have the size the rig expects.
#include <string>
#include <vector>

#include "fuzz/fuzz_support.h"
#include "fuzz/fuzz_targets.h"
#include "tracking/sequence.h"

namespace mcms::fuzz {

int FuzzPng(const uint8_t* data, size_t size) {
  const auto path = WriteInput(data, size, ".png");
  // Once with the rig's size (the seeds are 64 x 48) and once unchecked.
  for (const bool check_size : {true, false}) {
    ImageSequence seq;
    seq.frames = {0};
    seq.times_s = {0.0};
    seq.camera_dirs = {path.parent_path()};
    seq.image_names = {path.filename().string()};
    if (check_size) seq.image_sizes = {{64, 48}};
    std::vector<std::string> problems;
    ExpectInputError(path.string(), [&] {
      const std::vector<cv::Mat> im = LoadFrameImages(seq, 0, &problems);
      if (im.size() != 1) throw std::logic_error("LoadFrameImages: expected one image per camera");
      if (im[0].empty() && (problems.size() != 1 || problems[0].find(path.string()) == std::string::npos))
        throw std::logic_error("LoadFrameImages: an empty image without a reason naming the file");
      if (check_size && !im[0].empty() && (im[0].cols != 64 || im[0].rows != 48))
        throw std::logic_error("LoadFrameImages: an image of another size than the rig's");
    });
  }
  return 0;
}

}  // namespace mcms::fuzz
