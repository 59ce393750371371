// The target descriptions: the tracked ball target (tracking/target.h) and the
// calibration board in Kalibr's format (calib/calibration_board.h).
#include "calib/calibration_board.h"
#include "fuzz/fuzz_support.h"
#include "fuzz/fuzz_targets.h"
#include "tracking/target.h"

namespace mcms::fuzz {

int FuzzTarget(const uint8_t* data, size_t size) {
  const auto path = WriteInput(data, size, ".yaml");
  ExpectInputError(path.string(), [&] { (void)Target::Read(path); });
  ExpectInputError(path.string(), [&] {
    const CalibrationBoard b = CalibrationBoard::Read(path);
    std::string why;
    if (!b.IsValid(&why)) throw std::logic_error(std::string("CalibrationBoard::Read accepted an invalid board: ").append(why));
  });
  return 0;
}

}  // namespace mcms::fuzz
