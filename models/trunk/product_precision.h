// Copyright 2026 The tactfunc Authors.
//
// The precision of the trunks' batched matrix products, for the whole process.
//
// kFloat (the default): float operands and sums. kBfloat16: each product's operands are
// rounded to bfloat16 (8 significant bits against float's 24) and multiplied with
// AVX512_BF16's dot-product instruction, the sums kept in float: twice the float
// kernel's multiply-adds per instruction, each term of a sum off by at most about 2^-8
// of itself. Products of fewer than 16 inner terms or columns stay float (among them the
// first layer's, of the pixel coordinates). It applies to the products of the SIREN's
// and the photometric head's batched passes (forward, reverse, Hessian-vector products,
// weight gradients): fitting, encoding, meta-training, rendering. Parameters, latents,
// sines, losses and optimiser states stay float or double, and double passes are
// untouched. docs/BUILD.md ("bfloat16 products") describes the kernel and
// docs/BENCHMARKS.md what it buys in speed and costs in PSNR.
//
// Deterministic like the float kernel: the same inputs give the same bits on every run
// and thread count. Set it before work starts (before trunks are made or loaded, so that
// they pack their weights for it); passes running while it changes may mix the two.
#ifndef TACTFUNC_MODELS_TRUNK_PRODUCT_PRECISION_H_
#define TACTFUNC_MODELS_TRUNK_PRODUCT_PRECISION_H_

#include <string>

namespace tactfunc {

enum class ProductPrecision { kFloat, kBfloat16 };

// True when this CPU can run the precision (kBfloat16 needs AVX512_BF16).
bool ProductPrecisionAvailable(ProductPrecision precision);

// Sets the process's product precision. Throws std::invalid_argument, leaving it
// unchanged, when the CPU cannot run it.
void SetProductPrecision(ProductPrecision precision);
ProductPrecision GetProductPrecision();

// Sets a precision for one scope (throwing as SetProductPrecision does) and puts back
// the one before at its end.
class ScopedProductPrecision {
 public:
  explicit ScopedProductPrecision(ProductPrecision precision)
      : previous_(GetProductPrecision()) {
    SetProductPrecision(precision);
  }
  ~ScopedProductPrecision() { SetProductPrecision(previous_); }
  ScopedProductPrecision(const ScopedProductPrecision&) = delete;
  ScopedProductPrecision& operator=(const ScopedProductPrecision&) = delete;

 private:
  ProductPrecision previous_;
};

// "float" / "bf16", and back (std::invalid_argument naming the accepted values).
std::string ProductPrecisionName(ProductPrecision precision);
ProductPrecision ParseProductPrecision(const std::string& name);

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_TRUNK_PRODUCT_PRECISION_H_
