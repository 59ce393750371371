// Internal to the robot audit (audit/robot_audit.h): the candidates, the geometry the poses
// identify, and the greedy selection over them.
//
// Geometry first: the geometric parameters these poses identify (model/joint.h's error model,
// base, tool and the rigid body's points first, as calib-robot's analysis) are candidates one
// by one (joint_offset, link_length, link_twist of a DH table; the zero offsets of a URDF
// chain) and all at once (`geometry`). A non-geometric effect must also pass on top of the
// whole geometry. Each step is decided by the audit's one selection rule
// (audit/model_selection.h); ties are reported undecided with the poses that would tell them
// apart.
#pragma once

#include <functional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "audit/audit_report.h"
#include "audit/robot_audit_problem.h"

namespace mcms::robot_audit {

// A candidate of a greedy step: the terms of theta it frees, and what it names.
struct Option {
  std::string key;         // unique label: "joint_offset at joint 3", "error_motion at joint 2 (rx)"
  Extension ext;           // the catalog effect and where it acts
  std::vector<int> terms;  // parameter indices it frees
  // Preference in ties (model_selection rule 5): 0 a single physical cause, 1 the whole
  // geometry (broad), 2 error motion (a flexible harmonic family).
  int tier = 0;
  bool geometric = false;  // a geometric term (or all of them)
};

bool Wanted(const RobotAuditOptions& o, Effect e);
bool GeometryWanted(const RobotAuditOptions& o);

// The blocks of theta (pb->blocks, offset, P, lower, theta0) and the candidates that free
// them: the geometric terms and the rest of the catalog.
void MakeLayout(Problem* pb, const RobotLog& log, const RobotAuditOptions& o, std::vector<Option>* geometric,
                std::vector<Option>* others, std::vector<std::string>* notes);

// The geometric parameters these poses identify with the registration and the tool free,
// and the reason for each that is held.
struct Identifiable {
  std::vector<int> params;                                // geometry parameters of theta
  std::vector<std::pair<std::string, std::string>> held;  // name, reason
  // Registration or tool parameters these poses do not identify (a tool offset along an
  // axis that never turns, with a placement per station): held at the starting value.
  std::vector<std::pair<int, std::string>> held_base;
};
Identifiable GeometryIdentifiability(const Problem& pb, const Eigen::MatrixXd& noise, double tol);
// The name of geometric parameter `p` of theta (model/robot_model.h GeometryParameterNames).
std::string GeometryName(const Problem& pb, int p);

struct Tried {
  int option = -1;
  std::vector<int> terms;
  FitResult fit;
  double lr = 0.0, bic = 0.0, tau_sigma = 0.0;
  bool cv_done = false;
  HeldOut cv;
};

struct Finding {
  int option = -1;  // the stage's option; -1 = the whole geometry
  std::vector<int> terms;
  double lr = 0.0, bic = 0.0, ll_gain = 0.0, rms_before = 0.0, rms_after = 0.0, tau_sigma = 0.0;
  double base_cv_loglik = 0.0;  // held-out log-likelihood of the model before this step
  bool undecided = false;
  std::vector<Tried> group;  // undecided: every member, best first
  bool dropped = false;      // pruned at the end
};

struct SelectionResult {
  std::vector<Finding> findings;
  FitResult cur;
  bool cv_known = false;
  HeldOut cur_cv;
};

// Greedy forward selection over every candidate, from `start`: single geometric terms, the
// whole identifiable geometry (`geometry_terms`) and the non-geometric catalog, each step
// by the selection rule at family-wise rate `alpha`.
SelectionResult RunSelection(const Problem& pb, const std::vector<Option>& opts, const std::vector<int>& geometry_terms,
                             const FitResult& start, const RobotAuditOptions& o, double alpha,
                             std::set<std::string>* not_identifiable, std::vector<std::string>* notes,
                             NestedFits* nested, const std::function<void(const std::string&)>& say);

// A physical bound the data push against (a negative compliance or backlash wanted on top
// of the final model and the whole geometry): said in a note, not named.
void NoteViolatedBounds(const Problem& pb, const std::vector<Option>& opts, const Identifiable& ident,
                        const FitResult& fin, double alpha_selection, const RobotAuditOptions& o,
                        AuditReport* report);

// Poses that best separate two fitted models: their predicted tool difference against the
// noise, over poses drawn within the joint limits and near the logged ones.
RobotAuditResult::NextPoses SeparatingPoses(const Problem& pb, const RobotLog& log, const Tried& A, const Tried& B,
                                            const std::string& la, const std::string& lb, int count);

}  // namespace mcms::robot_audit
