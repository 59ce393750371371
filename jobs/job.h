// The one signature of every job (jobs/*_job.h):
//
//   void RunXJob(const XJob& job, const JobOutput& out);
//
// XJob holds the inputs (paths as the user gave them) and the options. The job reads and
// checks them (InputError naming the input, nothing written), runs, writes its output
// folder as a whole (core/output_folder.h), gives its report text to out.print as it is
// made (the CLI prints it to stdout, a test or a binding collects it) and its progress
// lines to out.progress (empty: none). The progress bars of long loops (core/progress.h)
// go to stderr unless the job's `quiet` is set.
#pragma once

#include <functional>
#include <string>

namespace mcms {

struct JobOutput {
  std::function<void(const std::string&)> print;     // the report text
  std::function<void(const std::string&)> progress;  // progress lines (may be empty)
  void Print(const std::string& s) const {
    if (print) print(s);
  }
  void Progress(const std::string& s) const {
    if (progress) progress(s);
  }
};

}  // namespace mcms
