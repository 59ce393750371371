// mcms convert-robot: a robot description in the other form (model/urdf.h): a DH table
// (YAML) written as a URDF a ROS user loads, or a URDF chain written as mcms's YAML
// (`convention: urdf`). The forward kinematics of both are the same.
#include <cstdio>
#include <memory>
#include <string>

#include "app/commands.h"
#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"
#include "model/robot_model.h"
#include "model/urdf.h"

namespace mcms::app {
namespace {

struct ConvertRobotArgs {
  std::string input, output, base_link, tip_link;
};

int RunConvertRobot(const ConvertRobotArgs& a) {
  if (a.output.empty()) Throw("convert-robot: the output file is missing; give -o ROBOT.urdf or -o ROBOT.yaml");
  RequireOutputsSpareInputs({{a.output, "convert-robot -o"}}, {a.input});
  std::string ext = std::filesystem::path(a.output).extension().string();
  for (auto& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext != ".urdf" && ext != ".yaml" && ext != ".yml")
    Throw("convert-robot -o ", a.output, ": the output's extension says its form; give .urdf or .yaml");
  RequireWritableFile(a.output, "convert-robot -o");
  if (a.input.empty() && (!a.base_link.empty() || !a.tip_link.empty()))
    Throw("convert-robot: --base-link and --tip-link pick a chain of a URDF robot; give it as ROBOT");
  const RobotModel robot = a.input.empty() ? RobotModel::Default() : RobotModel::Read(a.input, {a.base_link, a.tip_link});
  if (ext == ".urdf")
    WriteUrdf(a.output, robot);
  else
    robot.Write(a.output);
  std::printf("wrote %s: robot '%s', %d joints\n", a.output.c_str(), robot.Name().c_str(), robot.NumJoints());
  return 0;
}

const McmsCommand kConvertRobot([](CLI::App& app) {
  auto args = std::make_shared<ConvertRobotArgs>();
  CLI::App* sub = app.add_subcommand(
      "convert-robot",
      "Write a robot description in the other form: a DH table (YAML) as a URDF, or a URDF chain as YAML "
      "(convention: urdf); the forward kinematics are the same (masses as inertials; a URDF cannot hold error "
      "motion or encoder noise)");
  sub->add_option("ROBOT", args->input, "robot description: YAML or URDF (default: the built-in KUKA KR 5 arc)")
      ->check(CLI::ExistingFile);
  sub->add_option("-o,--output", args->output, "FILE.urdf or FILE.yaml")->required();
  sub->add_option("--base-link", args->base_link, "URDF input: the chain's base link (default: the root)");
  sub->add_option("--tip-link", args->tip_link, "URDF input: the chain's tip link (default: the unambiguous leaf)");
  return std::make_pair(sub, Runner([args] { return RunConvertRobot(*args); }));
});

}  // namespace
}  // namespace mcms::app
