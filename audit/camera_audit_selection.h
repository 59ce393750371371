// The camera audit's selection (audit/camera_audit.h is the entry): the residual tests of
// a model, the noise scales, each round's candidates fitted and judged, the refits after
// an effect is taken, backward pruning, and the effects the data cannot tell apart.
// Internal to the camera audit.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "audit/camera_audit_problem.h"

namespace mcms::camera_audit {

// The residual tests of a model (terms, per-camera noise scales) on the leave-one-out
// residuals the auditor holds: each camera's chi-square, allowing the noise tolerance,
// two-sided (a noise model too pessimistic is also wrong), at alpha / (4 cameras); and each
// camera's whitened residuals (u, v) against time (lag-1 autocorrelation, trend), the
// position in the view (u, v, distance from the image centre) and the distance to the
// camera, Bonferroni over their number at alpha / 4: an effect the catalog lacks shows
// here first. All tests into *tests (the residual tests sorted by p), a line for the notes
// into *note, the whitened residuals into *residuals (optional); returns the number of
// scalar residuals and their chi-square (*chi2_total).
long TestModel(const Auditor& a, const CameraRig& rig, const CameraAuditOptions& options,
               const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale,
               std::vector<AuditTest>* tests_out, std::string* note, std::vector<std::string>* unaudited,
               double* chi2_total, std::vector<std::vector<WhitenedResidual>>* residuals = nullptr);

// The nominal model's tests, into res->report.tests (the failed ones and the three
// strongest residual tests besides) and res->residuals; returns the number of scalar
// residuals.
long TestNominalModel(Auditor& a, const CameraRig& rig, const CameraAuditOptions& options,
                      const std::vector<CameraModelTerm>& terms, CameraAuditResult* res_out);

// The noise model first: each camera's scale, fitted within the tolerance band.
void FitNoiseScales(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options,
                    const std::vector<CameraModelTerm>& terms, std::vector<double>* scale_out, AuditReport* rep_out);

// How a unit's fit treats the camera's noise scale: free once named, else within the band;
// a ball unit has none.
ScaleMode UnitScaleMode(bool cam_unit, int u, const std::vector<bool>& noise_named);

// The candidates of one selection round, each fitted on all data and on the folds, with
// its likelihood ratio and held-out gain against its unit's current model; *tested
// receives the number of single candidates (the pairs fitted count on top of it).
std::vector<Candidate> RoundCandidates(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options,
                                       const std::vector<CameraModelTerm>& terms, const std::vector<double>& scale,
                                       const std::set<std::pair<bool, int>>& blocked,
                                       const std::vector<bool>& noise_named, int* tested);

// After an effect is taken: every unit's terms fitted again on the poses re-fitted with
// it, and the poses again, until the cameras' leave-one-out log-likelihood gains less than
// half a nat in a sweep (at most `iterations` sweeps: two moved cameras pull each other's
// poses, and the sweeps converge by a constant factor each). A term fitted while another camera's fault
// was still unmodelled carries that fault's pull on the leave-one-out poses; once the
// fault is in the model the pull is gone, and the term must be fitted without it, or its
// stale part is charged to the next round's candidates elsewhere.
void RefitUnits(Auditor& a, const std::vector<bool>& noise_named, int iterations,
                std::vector<CameraModelTerm>* terms_out, std::vector<double>* scale_out);

// Backward pruning: an effect named early (e.g. the noise scale, taking up the residual of
// a large effect named later) must still earn its place once the others are in: each
// named effect is removed in turn when the likelihood ratio for it, on the poses
// re-fitted with every effect, no longer passes the test or its BIC gain is <= 0.
void PruneNamedEffects(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options, double ln_n,
                       std::vector<CameraModelTerm>* terms_out, std::vector<double>* scale_out,
                       std::vector<bool>* noise_named_out, AuditReport* rep_out);

// A move named while another camera's fault was still unmodelled may have won by what its
// six parameters took of that fault through the shared poses (a 3-camera rig: a focal length
// of one camera and a k1 of another; the move, a shift along the axis, took the focal
// length's place). Once every effect is in, each named move for the whole recording is
// judged again against its camera's simpler intrinsic explanations (focal length, principal
// point, both), each fitted in its place with every other term and the poses (the joint
// fit): where the move's extra parameters are no evidence against one of them (its
// likelihood ratio over it below the chi-square quantile at the recording's false-alarm
// rate itself, without the candidates' Bonferroni: the move keeps its place on any evidence
// that it is one), the one of these with the best BIC that earns its own place (the test,
// BIC and a held-out gain, as the move did) is named instead, with a note.
void SimplifyNamedMoves(Auditor& a, const CameraRig& rig, int nb, const CameraAuditOptions& options, double ln_n,
                        const std::vector<double>& scale, const std::vector<bool>& noise_named,
                        std::vector<CameraModelTerm>* terms_io, AuditReport* rep);

// A last fit of every unit with named effects on the poses re-fitted with all of them
// (the noise scale, in particular, whitens with the pose covariances of its own value).
void RefitNamedUnits(Auditor& a, const CameraRig& rig, const std::vector<bool>& noise_named,
                     std::vector<CameraModelTerm>* terms_out, std::vector<double>* scale_out, AuditReport* rep_out);

// Moves for the whole recording at all cameras but one (or at all) are not identifiable:
// the target's poses are free, so camera a moved by Ma and camera b by Mb give the same
// images as every other camera moved by Ma^-1 and b by Ma^-1 Mb (two cameras: a move of
// either). Time offsets likewise: the same offset at every camera is a shift of the
// target's (free) trajectory, so offsets (0, a, b) of three cameras give the same images as
// (-a, 0, b - a) or (-b, a - b, 0). The images cannot say which cameras moved (or lag); the
// terms stay in the model (the poses need them) but are reported as one undecided group of
// every camera seen.
void UndecideUnidentifiable(const Auditor& a, const CameraRig& rig, Effect effect, std::vector<CameraModelTerm>* terms,
                            AuditReport* rep);

// A named intrinsic effect or time offset is judged against what could stand in its place
// with as many parameters: the same effect at every other camera, and the camera's other
// effects of its size (focal length, k1 and time offset have one parameter each), by the
// joint fit (Auditor::JointFit: every term and every frame's pose fitted together). A fault
// of one camera pulls the poses all cameras share, so in a small rig the same effect
// elsewhere, with the other terms, may explain the images as well; and a focal length and a
// k1 differ only in how the image scales with the distance from its centre, which a target
// seen near the centre does not show. Where a stand-in explains the images as well (within
// undecided_nats of log-likelihood), the images do not say which it is: the group is
// reported undecided and the term kept in the model, unnamed.
void UndecideSwappableEffects(const Auditor& a, const CameraRig& rig, const CameraAuditOptions& options,
                              const std::vector<double>& scale, const std::vector<bool>& noise_named,
                              std::vector<CameraModelTerm>* terms_io, AuditReport* rep);

// The named terms' values and sigmas from the joint fit (every term and every frame's pose
// together: the maximum likelihood, its covariance with the poses marginalised), not from
// each unit's fit on leave-one-out poses, which a neighbour's fault still pulls and whose
// sigma leaves out the poses' own error. The noise scales stay the units' fits.
void JointEstimates(const Auditor& a, const CameraRig& rig, const std::vector<double>& scale,
                    std::vector<CameraModelTerm>* terms_io, AuditReport* rep);

}  // namespace mcms::camera_audit
