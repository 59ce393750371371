#include "audit/audit_report.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <cstdio>
#include <sstream>

#include <nlohmann/json.hpp>

#include "core/io.h"

namespace mcms {
namespace {

// JSON has no NaN or infinity: they are written as null.
nlohmann::json Number(double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); }

nlohmann::json Map(const std::vector<std::pair<std::string, double>>& kv) {
  nlohmann::json j = nlohmann::json::object();
  for (const auto& [k, v] : kv) j[k] = Number(v);
  return j;
}

nlohmann::json EffectJson(const AuditEffect& e) {
  nlohmann::json j = {{"name", e.name},
                      {"where", e.where},
                      {"parameters", Map(e.parameters)},
                      {"sigma", Map(e.sigma)},
                      {"heldout_rms_before", Number(e.heldout_rms_before)},
                      {"heldout_rms_after", Number(e.heldout_rms_after)},
                      {"heldout_loglik_gain", Number(e.heldout_loglik_gain)},
                      {"bic_gain", Number(e.bic_gain)}};
  if (!e.rms_unit.empty()) j["rms_unit"] = e.rms_unit;
  for (const auto& [key, value] : e.labels) j["parameters"][key] = value;
  if (!e.held.empty()) {
    j["held"] = nlohmann::json::object();
    for (const auto& [key, why] : e.held) j["held"][key] = why;
  }
  return j;
}

std::string Fmt(const char* fmt, double v) {
  char b[64];
  std::snprintf(b, sizeof b, fmt, v);
  return b;
}

}  // namespace

bool NestedFits::Record(double lr, double contained_loglik) {
  const double rel = lr / std::max(1.0, std::abs(contained_loglik));
  ++count;
  if (!(rel >= worst_relative_lr)) worst_relative_lr = std::isfinite(rel) ? rel : -std::numeric_limits<double>::infinity();
  const bool ok = rel >= -kTolerance;
  if (!ok) ++failed;
  return ok;
}

void NestedFits::Merge(const NestedFits& o) {
  count += o.count;
  failed += o.failed;
  worst_relative_lr = std::min(worst_relative_lr, o.worst_relative_lr);
}

void AuditReport::Merge(const AuditReport& o) {
  nested.Merge(o.nested);
  const long n = nominal_n + o.nominal_n;
  if (n > 0) nominal_chi2_per_dof = (nominal_chi2_per_dof * nominal_n + o.nominal_chi2_per_dof * o.nominal_n) / n;
  nominal_n = n;
  clean = clean && o.clean;
  tests.insert(tests.end(), o.tests.begin(), o.tests.end());
  tests_after.insert(tests_after.end(), o.tests_after.begin(), o.tests_after.end());
  tests_after_run += o.tests_after_run;
  for (AuditEffect e : o.effects) {
    if (e.rms_unit.empty() && o.rms_unit != rms_unit) e.rms_unit = o.rms_unit;
    effects.push_back(e);
  }
  // Sizes stay index-aligned with the groups: pad the side that has none.
  if (!o.undecided_effects.empty() || !undecided_effects.empty()) {
    undecided_effects.resize(undecided.size());
    auto other = o.undecided_effects;
    other.resize(o.undecided.size());
    undecided_effects.insert(undecided_effects.end(), other.begin(), other.end());
  }
  undecided.insert(undecided.end(), o.undecided.begin(), o.undecided.end());
  notes.insert(notes.end(), o.notes.begin(), o.notes.end());
  validation.insert(validation.end(), o.validation.begin(), o.validation.end());
}

std::string AuditReport::ToJson() const {
  nlohmann::json j;
  j["mode"] = mode;
  j["nominal"] = {{"chi2_per_dof", Number(nominal_chi2_per_dof)}, {"n", nominal_n}};
  j["clean"] = clean;
  j["rms_unit"] = rms_unit;
  j["tests"] = nlohmann::json::array();
  for (const auto& t : tests)
    j["tests"].push_back(
        {{"name", t.name}, {"statistic", Number(t.statistic)}, {"p_value", Number(t.p_value)}, {"failed", t.failed}});
  if (tests_after_run > 0) {
    j["tests_after"] = nlohmann::json::array();
    for (const auto& t : tests_after)
      j["tests_after"].push_back({{"name", t.name},
                                  {"statistic", Number(t.statistic)},
                                  {"p_value", Number(t.p_value)},
                                  {"failed", t.failed}});
  }
  j["effects"] = nlohmann::json::array();
  for (const auto& e : effects) j["effects"].push_back(EffectJson(e));
  j["undecided"] = undecided;
  if (!undecided_effects.empty()) {
    j["undecided_effects"] = nlohmann::json::array();
    for (const auto& g : undecided_effects) {
      nlohmann::json a = nlohmann::json::array();
      for (const auto& e : g) a.push_back(EffectJson(e));
      j["undecided_effects"].push_back(a);
    }
  }
  j["notes"] = notes;
  j["nested_fits"] = {{"count", nested.count},
                      {"worst_relative_lr", Number(nested.worst_relative_lr)},
                      {"failed", nested.failed}};
  if (!validation.empty()) j["validation"] = ValidationJson(validation);
  return j.dump(2) + "\n";
}

std::string AuditReport::Text() const {
  std::ostringstream o;
  o << "audit (" << mode << "): nominal model chi2/dof " << Fmt("%.3f", nominal_chi2_per_dof) << " over " << nominal_n
    << " residuals\n";
  for (const auto& t : tests)
    o << "  test " << t.name << ": statistic " << Fmt("%.4g", t.statistic) << ", p " << Fmt("%.3g", t.p_value)
      << (t.failed ? "  FAILED" : "") << "\n";
  if (effects.empty() && undecided.empty()) {
    o << (clean ? "no effect found: the nominal model explains the data within its noise\n"
                : "no effect from the catalog explains what the tests found\n");
  }
  const auto Sizes = [&](const AuditEffect& e) {
    for (const auto& [key, value] : e.labels) o << " " << key << " = " << value;
    for (size_t k = 0; k < e.parameters.size(); ++k) {
      const std::string unit = k < e.units.size() ? e.units[k] : std::string();
      if ((unit == "rad" || unit == "m") && k < e.sigma.size() && std::isfinite(e.sigma[k].second)) {
        // mrad or mm, to the digits two significant ones of the sigma take.
        const double v = e.parameters[k].second * 1e3, sg = e.sigma[k].second * 1e3;
        const int digits = sg > 0 ? std::clamp(1 - static_cast<int>(std::floor(std::log10(sg))), 0, 9) : 4;
        std::string name = e.parameters[k].first;
        for (const std::string suffix : {"_rad", "_m"})
          if (name.size() > suffix.size() && name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0)
            name.resize(name.size() - suffix.size());
        char b[160];
        std::snprintf(b, sizeof b, " %s = %.*f +- %.*f %s", name.c_str(), digits, v, digits, sg,
                      unit == "rad" ? "mrad" : "mm");
        o << b;
        continue;
      }
      o << " " << e.parameters[k].first << " = " << Fmt("%.6g", e.parameters[k].second);
      if (k < e.sigma.size()) o << " +- " << Fmt("%.2g", e.sigma[k].second);
      if (!unit.empty()) o << " " << unit;
    }
  };
  // Held-out RMS of positions in mm (the robot's), else in the mode's unit.
  const auto Rms = [&](const AuditEffect& e) {
    const std::string unit = e.rms_unit.empty() ? rms_unit : e.rms_unit;
    if (unit == "m")
      return Fmt("%.4g", e.heldout_rms_before * 1e3) + " -> " + Fmt("%.4g", e.heldout_rms_after * 1e3) + " mm";
    return Fmt("%.4g", e.heldout_rms_before) + " -> " + Fmt("%.4g", e.heldout_rms_after) + " " + unit;
  };
  for (const auto& e : effects) {
    o << "effect " << e.name << (e.where.empty() ? "" : " at " + e.where) << ":";
    Sizes(e);
    o << "\n    held-out RMS " << Rms(e) << ", held-out log-likelihood gain " << Fmt("%.1f", e.heldout_loglik_gain)
      << ", BIC gain " << Fmt("%.1f", e.bic_gain) << "\n";
    for (const auto& [key, why] : e.held) o << "    held " << key << ": " << why << "\n";
  }
  // Other sessions, frozen, beside the named causes (what a metrologist reads first).
  o << ValidationText(validation);
  for (size_t g = 0; g < undecided.size(); ++g) {
    o << "undecided: these explain the same residual equally well:";
    for (const auto& s : undecided[g]) o << " [" << s << "]";
    o << "\n";
    if (g < undecided_effects.size())
      for (const auto& e : undecided_effects[g]) {
        o << "    " << e.name << (e.where.empty() ? "" : " at " + e.where) << ":";
        Sizes(e);
        o << " (held-out gain " << Fmt("%.1f", e.heldout_loglik_gain) << ", BIC gain " << Fmt("%.1f", e.bic_gain)
          << ")\n";
      }
  }
  // Whenever the final model holds a term (named, or an undecided group's in the camera audit).
  if (tests_after_run > 0) {
    if (tests_after.empty())
      o << "with the final model, every one of the " << tests_after_run << " residual tests passes\n";
    else
      o << "what remains unexplained: with the final model, " << tests_after.size() << " of the " << tests_after_run
        << " residual tests still fail\n";
    for (const auto& t : tests_after)
      o << "  still failing: " << t.name << ": statistic " << Fmt("%.4g", t.statistic) << ", p "
        << Fmt("%.3g", t.p_value) << "\n";
  }
  for (const auto& n : notes) o << "note: " << n << "\n";
  return o.str();
}

void AuditReport::WriteJson(const std::filesystem::path& path) const {
  const std::string s = ToJson();
  WriteFileAtomically(path, [&](std::ostream& os) { os << s; });
}

}  // namespace mcms
