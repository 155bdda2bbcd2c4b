// Copyright 2026 The tactfunc Authors.
#include "apps/command.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <thread>

#include "CLI/CLI.hpp"
#include "estimation/functaset/functaset.h"
#include "models/trunk/product_precision.h"

namespace tactfunc::apps {

void EmitJson(const nlohmann::json& figures) {
  std::cout << figures.dump() << std::endl;
}

std::vector<int> ParsePositiveIntList(const std::string& text, const std::string& flag,
                                      const std::string& what) {
  const UsageError error(flag + ": expected a comma-separated list of " + what + " >= 1, got '" +
                         text + "'");
  std::vector<int> values;
  for (const std::string& item : SplitList(text)) {
    std::size_t used = 0;
    int value = 0;
    try {
      value = std::stoi(item, &used);
    } catch (const std::exception&) {
      throw error;
    }
    if (used != item.size() || value < 1) throw error;
    values.push_back(value);
  }
  if (values.empty()) throw error;
  return values;
}

std::vector<std::string> SplitList(const std::string& text) {
  std::vector<std::string> items;
  std::string current;
  auto flush = [&]() {
    const auto begin = current.find_first_not_of(" \t");
    const auto end = current.find_last_not_of(" \t");
    if (begin != std::string::npos) items.push_back(current.substr(begin, end - begin + 1));
    current.clear();
  };
  for (char ch : text) {
    if (ch == ',') {
      flush();
    } else {
      current += ch;
    }
  }
  flush();
  return items;
}

void AddProductPrecisionFlag(CLI::App* sub, std::string* value, bool as_functaset) {
  sub->add_option("--products", *value,
                  as_functaset
                      ? "Precision of the trunk's matrix products: float or bf16 (default: the "
                        "one the functaset was encoded with, where this CPU runs it; "
                        "docs/BUILD.md)"
                      : "Precision of the trunk's matrix products: float (default) or bf16 "
                        "(operands rounded to bfloat16, sums in float; needs AVX512_BF16; faster "
                        "than float on some such CPUs, slower on others, at a small cost in "
                        "accuracy: docs/BUILD.md)")
      ->check(CLI::IsMember({"float", "bf16"}));
}

void ApplyProductPrecision(const std::string& value) {
  const ProductPrecision precision = ParseProductPrecision(value);
  if (!ProductPrecisionAvailable(precision)) {
    throw UsageError("--products " + value +
                     ": this CPU lacks AVX512_BF16, which bfloat16 products need; use float");
  }
  SetProductPrecision(precision);
}

std::string ProductPrecisionFor(const std::string& flag, const Functaset& functaset,
                                const std::string& path, const std::string& command) {
  if (!flag.empty()) return flag;
  bool bf16 = false;
  for (SensorKind sensor : functaset.sensors()) bf16 = bf16 || functaset.products(sensor) == "bf16";
  if (!bf16) return "float";
  if (!ProductPrecisionAvailable(ProductPrecision::kBfloat16)) {
    std::cerr << command << ": " << path << " was encoded with bf16 products, which this CPU "
              << "lacks (AVX512_BF16); rendering in float, its PSNRs may differ a little\n";
    return "float";
  }
  std::cout << command << ": bf16 products, as " << path << " was encoded\n";
  return "bf16";
}

int ResolveThreads(int requested) {
  if (requested > 0) return requested;
  return static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

std::string FormatBytes(std::uint64_t bytes) {
  char buffer[32];
  if (bytes >= 1000ull * 1000 * 1000) {
    std::snprintf(buffer, sizeof(buffer), "%.2f GB", bytes / 1e9);
  } else if (bytes >= 1000ull * 1000) {
    std::snprintf(buffer, sizeof(buffer), "%.2f MB", bytes / 1e6);
  } else if (bytes >= 1000ull) {
    std::snprintf(buffer, sizeof(buffer), "%.1f kB", bytes / 1e3);
  } else {
    std::snprintf(buffer, sizeof(buffer), "%llu B", static_cast<unsigned long long>(bytes));
  }
  return buffer;
}

nlohmann::json NumberOrNull(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

std::string FormatFixed(double value, int digits, const char* missing) {
  if (std::isnan(value)) return missing;
  if (std::isinf(value)) return value > 0 ? "inf" : "-inf";
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.*f", digits, value);
  return buffer;
}

}  // namespace tactfunc::apps
