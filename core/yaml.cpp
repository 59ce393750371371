#include "core/yaml.h"

#include <yaml-cpp/depthguard.h>

#include <map>

#include "core/error.h"

namespace mcms {
namespace {

// Nodes a document may hold once its aliases are expanded: every mcms file has a few
// thousand; a few hundred bytes of nested aliases (a "billion laughs" file) expand to
// billions, which every reader would walk.
constexpr long kMaxYamlNodes = 2000000;

void CheckUniqueKeys(const YAML::Node& n, const std::string& source, int depth, long* nodes) {
  if (depth > 256) Throw(source, ": nested more than 256 levels deep");
  if (++*nodes > kMaxYamlNodes)
    Throw(source, ": more than ", kMaxYamlNodes,
          " values once its aliases (*name) are expanded: nested aliases that multiply (a YAML bomb?)");
  if (n.IsMap()) {
    std::map<std::string, int> seen;  // key -> line (1-based)
    for (const auto& kv : n) {
      if (kv.first.IsScalar()) {
        const std::string key = kv.first.Scalar();
        const int line = kv.first.Mark().line + 1;
        const auto [it, fresh] = seen.emplace(key, line);
        if (!fresh)
          Throw(source, " line ", line, ": key '", key, "' appears twice (lines ", it->second, " and ", line,
                "); a map holds each key once: remove one");
      }
      CheckUniqueKeys(kv.second, source, depth + 1, nodes);
    }
  } else if (n.IsSequence()) {
    for (const auto& e : n) CheckUniqueKeys(e, source, depth + 1, nodes);
  }
}

}  // namespace

YAML::Node LoadYaml(const std::string& text, const std::string& source) {
  YAML::Node root;
  try {
    root = YAML::Load(text);
  } catch (const YAML::DeepRecursion& e) {
    // yaml-cpp's own guard says only "bad file".
    Throw(source, " line ", e.mark.line + 1, ": nested more than ", e.depth(), " levels deep (no robot, rig or "
          "scenario file nests beyond a few)");
  }
  long nodes = 0;
  CheckUniqueKeys(root, source, 0, &nodes);
  return root;
}

}  // namespace mcms
