// Copyright 2026 The tactfunc Authors.
// The Eigen configuration tactfunc shares with Ceres (docs/BUILD.md): 16-byte alignment
// for the Eigen types that cross Ceres' interface, and Ceres linked as the shared library,
// whose own copies of Eigen's inline allocation code stay private to it.
#include <dlfcn.h>

#include <cstdint>
#include <string>

#include "Eigen/Core"
#include "ceres/ceres.h"
#include "gtest/gtest.h"

static_assert(EIGEN_MAX_ALIGN_BYTES == 16,
              "tactfunc objects must compile with -DEIGEN_MAX_ALIGN_BYTES=16 (docs/BUILD.md)");

namespace tactfunc {
namespace {

TEST(EigenConfig, CeresIsTheSharedLibrary) {
  // Where the code of a Ceres entry point lives: in libceres.so, not in this program.
  void (*solve)(const ceres::Solver::Options&, ceres::Problem*, ceres::Solver::Summary*) =
      &ceres::Solve;
  Dl_info info{};
  ASSERT_NE(dladdr(reinterpret_cast<void*>(solve), &info), 0);
  ASSERT_NE(info.dli_fname, nullptr);
  EXPECT_NE(std::string(info.dli_fname).find("libceres.so"), std::string::npos)
      << "ceres::Solve is in " << info.dli_fname
      << ": Ceres is linked statically (cmake/TactfuncSharedCeres.cmake)";
}

// A heap array from Eigen's allocator goes back to Eigen's free, with the alignment the
// vectorised kernels were compiled for.
TEST(EigenConfig, HeapArraysAreAlignedForThePacketSize) {
  for (Eigen::Index n : {3, 256, 1 << 16}) {
    Eigen::MatrixXd m(n, 2);
    EXPECT_EQ(reinterpret_cast<std::uintptr_t>(m.data()) % EIGEN_DEFAULT_ALIGN_BYTES, 0u);
  }
}

}  // namespace
}  // namespace tactfunc
