// Copyright 2026 The tactfunc Authors.
// The Eigen configuration every tactfunc object must share with the static Ceres library
// (docs/BUILD.md): 16-byte alignment, and heap arrays from plain malloc/free, so that a
// buffer allocated by Ceres' copy of Eigen's inline allocator and freed by ours (or the
// reverse) is the same kind of pointer.
#include <cstdint>

#include "Eigen/Core"
#include "gtest/gtest.h"

static_assert(EIGEN_MAX_ALIGN_BYTES == 16,
              "tactfunc objects must compile with -DEIGEN_MAX_ALIGN_BYTES=16 (docs/BUILD.md)");
static_assert(EIGEN_MALLOC_ALREADY_ALIGNED == 1,
              "tactfunc objects must compile with -DEIGEN_MALLOC_ALREADY_ALIGNED=1: otherwise "
              "Eigen's inline aligned_malloc/aligned_free differ from the static Ceres' copies "
              "(docs/BUILD.md)");

namespace tactfunc {
namespace {

// aligned_malloc's pointer goes to plain free (what Ceres' copy of aligned_free does), and
// plain malloc's to aligned_free (what ours does): both must be valid, whichever copy of
// the inline functions the linker kept.
TEST(EigenConfig, AlignedAllocationsAreMallocPointers) {
  for (std::size_t bytes : {16u, 4096u, 1u << 20}) {
    void* p = Eigen::internal::aligned_malloc(bytes);
    ASSERT_NE(p, nullptr);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(p) % 16, 0u);
    std::free(p);
    void* q = std::malloc(bytes);
    ASSERT_NE(q, nullptr);
    Eigen::internal::aligned_free(q);
  }
}

}  // namespace
}  // namespace tactfunc
