// The CSV readers: core/io ReadCsv (every cell as a number), the truth poses of
// `mcms track --truth`, the ISO 9283 poses and path files, the fusion windows and the
// measured points/lines of `mcms fov-map`.
#include <cmath>

#include "calib/iso9283_report.h"
#include "core/io.h"
#include "fusion/log_fusion.h"
#include "fuzz/fuzz_support.h"
#include "fuzz/fuzz_targets.h"
#include "jobs/evaluation.h"
#include "audit/repeatability.h"

namespace mcms::fuzz {

int FuzzCsv(const uint8_t* data, size_t size) {
  const auto path = WriteInput(data, size, ".csv");
  const std::string name = path.string();
  ExpectInputError(name, [&] {
    const CsvTable t = ReadCsv(path);
    for (size_t r = 0; r < t.rows.size(); ++r)
      for (size_t c = 0; c < t.header.size(); ++c) ExpectInputError(name, [&] { (void)t.Number(r, static_cast<int>(c)); });
    for (const auto& h : t.header) (void)t.Column(h);
  });
  ExpectInputError(name, [&] { (void)ReadTruthPoses(path); });
  ExpectInputError(name, [&] { (void)EvaluateIso9283Files(path, {}); });
  ExpectInputError(name, [&] { (void)EvaluateIso9283Files(path, path); });
  ExpectInputError(name, [&] { (void)ReadFusionWindows(path); });
  ExpectInputError(name, [&] { (void)ReadMeasuredPoints(path); });
  ExpectInputError(name, [&] { (void)ReadMeasuredLines(path); });
  return 0;
}

}  // namespace mcms::fuzz
