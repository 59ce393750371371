// The whole `mcms audit lens` job on the jobs floor (audit/lens_audit.h holds the audit).
#pragma once

#include <filesystem>
#include <functional>
#include <string>

#include "audit/lens_audit.h"
#include "jobs/job.h"

namespace mcms {

// The whole `mcms audit lens` job: read the model, audit it, write the output folder and
// the JSON report when asked (every output checked before the work, which takes minutes
// with a splined candidate, and against the input). `print` receives the report text.
struct LensAuditJob {
  std::filesystem::path model, output, json;  // output, json: empty = not written
  LensAuditOptions options;
};
void RunLensAuditJob(const LensAuditJob& job, const JobOutput& out);

}  // namespace mcms
