// The sensor logs of `mcms fuse` (tracker poses CSV, joint log, inclinometer log) and the
// measurement log of `mcms audit robot` (CSV; its YAML form is the robot target's).
#include "audit/robot_audit.h"
#include "fusion/sensor_logs.h"
#include "fuzz/fuzz_support.h"
#include "fuzz/fuzz_targets.h"
#include "model/robot_model.h"

namespace mcms::fuzz {

int FuzzLogs(const uint8_t* data, size_t size) {
  static const RobotModel robot = RobotModel::Default();
  const auto path = WriteInput(data, size, ".csv");
  const std::string name = path.string();
  ExpectInputError(name, [&] { (void)ReadTrackerLog(path); });
  ExpectInputError(name, [&] { (void)ReadJointLog(path, robot); });
  ExpectInputError(name, [&] { (void)ReadInclinometerLog(path); });
  ExpectInputError(name, [&] { (void)ReadRobotLog(path, robot); });
  return 0;
}

}  // namespace mcms::fuzz
