#include "app/commands.h"

#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstdint>
#include <memory>
#include <string>

#include <Eigen/Geometry>

#include "core/error.h"
#include "core/limits.h"

namespace mcms::app {

namespace {
std::vector<Registrar>& Registrars() {
  static std::vector<Registrar> r;
  return r;
}
std::vector<std::pair<CLI::App*, Runner>>& Registered() {
  static std::vector<std::pair<CLI::App*, Runner>> r;
  return r;
}
}  // namespace

McmsCommand::McmsCommand(Registrar r) { Registrars().push_back(std::move(r)); }

void RegisterCommands(CLI::App& app) {
  for (auto& r : Registrars()) Registered().push_back(r(app));
}

CLI::Validator SeedValidator() {
  return CLI::Validator(
      [](std::string& v) -> std::string {
        uint64_t seed = 0;
        const char* end = v.data() + v.size();
        const auto [p, ec] = std::from_chars(v.data(), end, seed);
        if (v.empty() || ec != std::errc() || p != end)
          return "seed '" + v + "' must be a whole number from 0 to 18446744073709551615 (2^64 - 1)";
        return std::string();
      },
      "SEED", "seed");
}

namespace {
CLI::Validator NumberAtLeast(bool strictly_positive) {
  return CLI::Validator(
      [strictly_positive](std::string& v) -> std::string {
        char* end = nullptr;
        const double x = std::strtod(v.c_str(), &end);
        const bool number = !v.empty() && end == v.c_str() + v.size() && std::isfinite(x);
        if (number && (strictly_positive ? x > 0 : x >= 0)) return std::string();
        return std::string("expected a number ") + (strictly_positive ? "> 0" : ">= 0") + ", found '" + v + "'";
      },
      strictly_positive ? "POSITIVE" : "NONNEGATIVE", strictly_positive ? "positive" : "non-negative");
}
}  // namespace

CLI::Validator PositiveNumber() { return NumberAtLeast(true); }

JobOutput CommandOutput(const std::string& command, bool quiet) {
  JobOutput out;
  out.print = [](const std::string& s) {
    std::fputs(s.c_str(), stdout);
    std::fflush(stdout);
  };
  if (!quiet)
    out.progress = [command](const std::string& s) { std::fprintf(stderr, "%s: %s\n", command.c_str(), s.c_str()); };
  return out;
}

Pose PoseFromArgs(const std::vector<double>& v, const std::string& who, const std::string& option) {
  if (v.size() != 7) Throw(who, ": ", option, " takes 7 numbers x y z qw qx qy qz (m, unit quaternion), got ", v.size());
  static const char* const kNames[7] = {"x", "y", "z", "qw", "qx", "qy", "qz"};
  for (size_t i = 0; i < v.size(); ++i)
    if (!std::isfinite(v[i]))
      Throw(who, ": ", option, " ", kNames[i], " is ", v[i], "; expected 7 finite numbers x y z qw qx qy qz");
  for (int i = 0; i < 3; ++i) CheckMagnitude(v[i], kMaxRobotLengthM, who + ": " + option + " " + kNames[i], "m");
  const Eigen::Quaterniond q(v[3], v[4], v[5], v[6]);
  if (!IsUnitQuaternion(q)) Throw(who, ": ", option, " quaternion has norm ", q.norm(), ", expected 1");
  return Pose::FromQuaternion(q.normalized(), Vec3(v[0], v[1], v[2]));
}
CLI::Validator NonNegativeNumber() { return NumberAtLeast(false); }

int RunSelected(CLI::App& app) {
  for (auto& [sub, run] : Registered())
    if (sub->parsed()) return run();
  (void)app;
  return 1;
}

}  // namespace mcms::app
