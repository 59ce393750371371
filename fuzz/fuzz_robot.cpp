// The robot descriptions (model/robot_model.h, from text: RobotModel::Parse) and the
// robot measurement files of `mcms calib-robot` (calib/robot_calibration.h).
#include <string>

#include "calib/robot_calibration.h"
#include "fuzz/fuzz_support.h"
#include "fuzz/fuzz_targets.h"
#include "model/robot_model.h"

namespace mcms::fuzz {

int FuzzRobot(const uint8_t* data, size_t size) {
  const std::string text(reinterpret_cast<const char*>(data), size);
  const std::string source = "robot file fuzz-input.yaml";
  ExpectInputError(source, [&] {
    const RobotModel m = RobotModel::Parse(text, source);
    // Read(Write(m)) reproduces m (robot_model.h): what was accepted is written readably.
    try {
      (void)RobotModel::Parse(m.ToYaml(), "written robot");
    } catch (const InputError& e) {
      throw std::logic_error(std::string("RobotModel::Parse refuses the ToYaml() of a model it accepted: ").append(e.what()));
    }
  });
  const auto path = WriteInput(data, size, ".yaml");
  ExpectInputError(path.string(), [&] { (void)ReadRobotMeasurements(path); });
  return 0;
}

}  // namespace mcms::fuzz
