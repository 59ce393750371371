// Subcommand registry of the mcms CLI. Each app/cmd_*.cpp registers its subcommands
// with a static McmsCommand object: a function that adds a CLI11 subcommand and
// returns the function that runs it. Commands parse options and call the library;
// no algorithm lives here. Errors: throw mcms::InputError (main prints it, exit 2).
#pragma once

#include <CLI/CLI.hpp>

#include <functional>
#include <string>
#include <vector>

#include "core/pose_math.h"
#include "jobs/job.h"

namespace mcms::app {

using Runner = std::function<int()>;
// Adds a subcommand to `app` and returns (the subcommand, its runner).
using Registrar = std::function<std::pair<CLI::App*, Runner>(CLI::App& app)>;

struct McmsCommand {
  explicit McmsCommand(Registrar r);
};

void RegisterCommands(CLI::App& app);

// Checks a --seed value: a whole number from 0 to 2^64 - 1 in decimal digits. CLI11 alone
// would wrap -1 to 2^64 - 1 and saturate larger values, giving one seed for many inputs.
CLI::Validator SeedValidator();
// A finite number > 0 (>= 0): CLI11's own checks print their range as 0 to 1.8e308 in
// 300 digits; these name what was expected and what was found.
CLI::Validator PositiveNumber();
CLI::Validator NonNegativeNumber();
int RunSelected(CLI::App& app);

// A pose given as 7 numbers x y z qw qx qy qz (--base-guess, --tool-guess): InputError
// naming `who` and `option` unless finite, the position within core/limits.h's robot size,
// and the quaternion of unit norm.
// What a command's job prints (jobs/job.h): its report on stdout (flushed), its progress
// lines on stderr as "<command>: <line>" unless quiet.
JobOutput CommandOutput(const std::string& command, bool quiet);

Pose PoseFromArgs(const std::vector<double>& v, const std::string& who, const std::string& option);

}  // namespace mcms::app
