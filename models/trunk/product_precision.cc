// Copyright 2026 The tactfunc Authors.
#include "models/trunk/product_precision.h"

#include <atomic>
#include <stdexcept>

#include "models/trunk/internal/small_gemm.h"

namespace tactfunc {
namespace {
std::atomic<ProductPrecision> g_precision{ProductPrecision::kFloat};
}  // namespace

bool ProductPrecisionAvailable(ProductPrecision precision) {
  return precision == ProductPrecision::kFloat || internal::HaveBfloat16Gemm();
}

void SetProductPrecision(ProductPrecision precision) {
  if (!ProductPrecisionAvailable(precision)) {
    throw std::invalid_argument("product precision " + ProductPrecisionName(precision) +
                                " needs a CPU with AVX512_BF16, which this one lacks");
  }
  g_precision.store(precision, std::memory_order_relaxed);
}

ProductPrecision GetProductPrecision() { return g_precision.load(std::memory_order_relaxed); }

std::string ProductPrecisionName(ProductPrecision precision) {
  return precision == ProductPrecision::kBfloat16 ? "bf16" : "float";
}

ProductPrecision ParseProductPrecision(const std::string& name) {
  if (name == "float") return ProductPrecision::kFloat;
  if (name == "bf16") return ProductPrecision::kBfloat16;
  throw std::invalid_argument("product precision must be float or bf16, got '" + name + "'");
}

}  // namespace tactfunc
