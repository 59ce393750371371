#include "jobs/lens_audit_job.h"

#include "core/error.h"
#include "core/io.h"
#include "core/output_folder.h"

namespace mcms {

void RunLensAuditJob(const LensAuditJob& job, const JobOutput& out) {
  const RunInputsRecord run_inputs;  // what it reads through its inputs is an input too
  std::string why;
  if (!job.options.IsValid(&why)) Throw("audit lens: ", why);
  RequireOutputsSpareInputs({{job.output, "audit lens -o", true}, {job.json, "audit lens --json"}}, {job.model});
  // Outputs are checked before the work (minutes with a splined candidate).
  if (!job.output.empty()) RequireReplaceableFolder(job.output, {"report.json"}, "audit lens", "audit lens -o");
  if (!job.json.empty()) RequireWritableFile(job.json, "audit lens --json");
  const MrcalOptimizationInputsData data = ReadMrcalOptimizationInputs(job.model);
  LensAuditOptions options = job.options;
  if (out.progress) options.progress = out.progress;
  const LensAuditResult r = AuditLens(data, options);
  out.Print(r.report.Text());
  if (!job.output.empty()) {
    WriteLensAuditFiles(r, job.output);
    out.Print("wrote " + job.output.string() + " (report.txt, report.json, residuals.csv, plots/" + r.camera + ".svg" +
          (r.chosen > 0 ? ", " + r.camera + ".cameramodel" : std::string()) + ")\n");
  }
  if (!job.json.empty()) {
    r.report.WriteJson(job.json);
    out.Print("wrote " + job.json.string() + "\n");
  }
}

}  // namespace mcms
