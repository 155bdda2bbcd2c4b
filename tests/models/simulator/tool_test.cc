// Copyright 2026 The tactfunc Authors.
#include "models/simulator/tool.h"

#include <cmath>
#include <set>
#include <stdexcept>
#include <string>

#include <boost/random/mersenne_twister.hpp>
#include <boost/random/uniform_real_distribution.hpp>

#include "gtest/gtest.h"
#include "models/core/internal/checks.h"

namespace tactfunc {
namespace {

using internal::kPi;

// The largest |h(p) - h(R(angle) p)| over `samples` random points of the footprint.
double LargestChangeUnderRotation(const Tool& tool, double angle, int samples,
                                  std::uint64_t seed) {
  boost::random::mt19937_64 engine(seed);
  const double radius = tool.footprint_radius();
  boost::random::uniform_real_distribution<double> coordinate(-radius, radius);
  const double c = std::cos(angle), s = std::sin(angle);
  double largest = 0.0;
  for (int i = 0; i < samples; ++i) {
    const double u = coordinate(engine), v = coordinate(engine);
    largest = std::max(largest, std::abs(tool.Height(u, v) -
                                         tool.Height(c * u - s * v, s * u + c * v)));
  }
  return largest;
}

TEST(ToolSet, HasTwelveToolsWithDistinctNamesInTheDocumentedOrder) {
  const std::vector<std::string> expected = {
      "lines2_30", "lines2_60", "lines2_90",  "lines3_20", "lines3_40", "lines5",
      "rod",       "hemisphere", "triangle", "square",    "l_shape",   "half_disc"};
  EXPECT_EQ(ToolNames(), expected);
  std::set<std::string> names(expected.begin(), expected.end());
  EXPECT_EQ(names.size(), 12u);
  for (const Tool& tool : ToolSet()) EXPECT_FALSE(tool.description().empty());
}

TEST(ToolSet, DocumentsTheSymmetryOrderOfEveryTool) {
  const std::vector<int> expected = {2, 2, 4, 1, 1, 2, 2, 0, 3, 4, 1, 1};
  for (std::size_t i = 0; i < ToolSet().size(); ++i) {
    EXPECT_EQ(ToolSet()[i].symmetry_order(), expected[i]) << ToolSet()[i].name();
  }
}

TEST(ToolSet, EveryFaceIsPositiveAndBoundedInsideItsFootprintAndZeroOutside) {
  for (const Tool& tool : ToolSet()) {
    SCOPED_TRACE(tool.name());
    EXPECT_GT(tool.max_height(), 1e-3);
    EXPECT_LT(tool.max_height(), 10e-3);
    EXPECT_GT(tool.footprint_radius(), 5e-3);
    EXPECT_LT(tool.footprint_radius(), 15e-3);
    const double radius = tool.footprint_radius();
    double highest = 0.0;
    const int n = 301;
    for (int i = 0; i < n; ++i) {
      for (int j = 0; j < n; ++j) {
        const double u = radius * (2.0 * i / (n - 1) - 1.0) * 1.2;
        const double v = radius * (2.0 * j / (n - 1) - 1.0) * 1.2;
        const double h = tool.Height(u, v);
        ASSERT_GE(h, 0.0);
        ASSERT_LE(h, tool.max_height() * (1.0 + 1e-12));
        if (std::hypot(u, v) > radius) {
          ASSERT_EQ(h, 0.0) << u << ", " << v;
        }
        highest = std::max(highest, h);
      }
    }
    EXPECT_GT(highest, 0.95 * tool.max_height());
  }
}

TEST(ToolSet, EveryFaceHasItsDocumentedSymmetry) {
  for (const Tool& tool : ToolSet()) {
    SCOPED_TRACE(tool.name());
    const int n = tool.symmetry_order();
    if (n == 0) {
      for (double angle : {0.3, 1.7, -2.9}) {
        EXPECT_LT(LargestChangeUnderRotation(tool, angle, 20000, 1), 1e-12);
      }
    } else {
      EXPECT_LT(LargestChangeUnderRotation(tool, 2.0 * kPi / n, 20000, 2), 1e-12);
    }
  }
}

TEST(ToolSet, NoFaceHasMoreSymmetryThanDocumented) {
  // C_n contains the turn 2 pi / m exactly when m divides n; every other turn must
  // move the face by a visible amount somewhere.
  for (const Tool& tool : ToolSet()) {
    const int n = tool.symmetry_order();
    if (n == 0) continue;
    for (int m : {2, 3, 4, 5, 6, 8}) {
      if (n % m == 0) continue;
      EXPECT_GT(LargestChangeUnderRotation(tool, 2.0 * kPi / m, 20000, 3), 0.5e-3)
          << tool.name() << " looks symmetric under 2 pi / " << m;
    }
  }
}

TEST(GetTool, FindsEveryToolByName) {
  for (const std::string& name : ToolNames()) EXPECT_EQ(GetTool(name).name(), name);
}

TEST(GetTool, ThrowsForAnUnknownNameListingTheValidOnes) {
  try {
    GetTool("spoon");
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("spoon"), std::string::npos);
    for (const std::string& name : ToolNames()) {
      EXPECT_NE(message.find(name), std::string::npos) << name;
    }
  }
}

TEST(Tool, RejectsANegativeSymmetryOrder) {
  EXPECT_THROW(Tool("t", "d", -1, [](double, double) { return 0.0; }, 1e-3, 1e-3),
               std::invalid_argument);
}

TEST(YawErrorModuloSymmetry, IsZeroForYawsRelatedByTheSymmetry) {
  EXPECT_NEAR(YawErrorModuloSymmetry(0.1, 0.1 + kPi, 2), 0.0, 1e-12);
  EXPECT_NEAR(YawErrorModuloSymmetry(0.1, 0.1 - 1.5 * kPi, 4), 0.0, 1e-12);
  EXPECT_NEAR(YawErrorModuloSymmetry(-1.0, -1.0 + 4.0 * kPi / 3.0, 3), 0.0, 1e-12);
}

TEST(YawErrorModuloSymmetry, MeasuresTheShortWayRound) {
  EXPECT_NEAR(YawErrorModuloSymmetry(0.1, 0.1 + kPi, 1), kPi, 1e-12);
  EXPECT_NEAR(YawErrorModuloSymmetry(-kPi + 0.05, kPi - 0.05, 1), 0.1, 1e-12);
  EXPECT_NEAR(YawErrorModuloSymmetry(0.0, 1.5 * kPi + 0.1, 4), 0.1, 1e-12);
  EXPECT_NEAR(YawErrorModuloSymmetry(0.2, 0.0, 2), 0.2, 1e-12);
  EXPECT_NEAR(YawErrorModuloSymmetry(0.0, 0.2, 2), 0.2, 1e-12);
}

TEST(YawErrorModuloSymmetry, StaysWithinZeroAndPiOverN) {
  boost::random::mt19937_64 engine(7);
  boost::random::uniform_real_distribution<double> yaw(-10.0, 10.0);
  for (int n = 1; n <= 4; ++n) {
    for (int i = 0; i < 1000; ++i) {
      const double e = YawErrorModuloSymmetry(yaw(engine), yaw(engine), n);
      EXPECT_GE(e, 0.0);
      EXPECT_LE(e, kPi / n + 1e-12);
    }
  }
}

TEST(YawErrorModuloSymmetry, IsZeroForContinuousSymmetryAndRejectsNegativeOrders) {
  EXPECT_EQ(YawErrorModuloSymmetry(0.3, 2.0, 0), 0.0);
  EXPECT_THROW(YawErrorModuloSymmetry(0.0, 0.0, -1), std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
