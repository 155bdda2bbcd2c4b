// Copyright 2026 The tactfunc Authors.
//
// The labels.csv reader: any text it accepts must format and parse back to the same
// rows (the writer and the reader agree).
#include <cstddef>
#include <cstdint>

#include "estimation/data/internal/labels_csv.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tactfunc;
  const std::string text(reinterpret_cast<const char*>(data), size);
  std::vector<internal::LabelRow> rows;
  try {
    rows = internal::ParseLabelsCsv(text, "fuzz/labels.csv");
  } catch (const DatasetError& e) {
    fuzz::CheckMessage(e.what(), "fuzz/labels.csv");
    return 0;
  }
  std::vector<internal::LabelRow> again;
  try {
    again = internal::ParseLabelsCsv(internal::FormatLabelsCsv(rows), "again.csv");
  } catch (const DatasetError& e) {
    fuzz::Finding(std::string("accepted rows do not parse back: ") + e.what());
  }
  if (again.size() != rows.size()) fuzz::Finding("round trip changed the row count");
  for (std::size_t i = 0; i < rows.size(); ++i) {
    if (again[i].frame != rows[i].frame || again[i].sensor != rows[i].sensor ||
        again[i].split != rows[i].split || again[i].label.has_value() != rows[i].label.has_value() ||
        (rows[i].label && !(*again[i].label == *rows[i].label))) {
      fuzz::Finding("round trip changed row " + std::to_string(i));
    }
  }
  return 0;
}
