// The one way YAML (and JSON) text is parsed: yaml-cpp, plus what it lets through. A map
// that holds a key twice is kept by yaml-cpp with both entries and read as the first;
// here it is an InputError naming the source, the key and both lines.
#pragma once

#include <string>

#include <yaml-cpp/yaml.h>

namespace mcms {

// YAML::Load(text); YAML::ParserException passes through (callers word it for their file).
// InputError "<source> line N: key 'k' appears twice (lines M and N); a map holds each key
// once" for a duplicated key at any depth.
YAML::Node LoadYaml(const std::string& text, const std::string& source);

}  // namespace mcms
