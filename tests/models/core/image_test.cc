// Copyright 2026 The tactfunc Authors.
#include "models/core/image.h"

#include <stdexcept>

#include "gtest/gtest.h"
#include "models/core/sensor.h"

namespace tactfunc {
namespace {

TEST(Image, StoresChannelsInterleavedRowMajor) {
  Image image(2, 3, 3, 0.0f);
  image.at(1, 2, 1) = 7.0f;
  EXPECT_EQ(image.data[(1 * 3 + 2) * 3 + 1], 7.0f);
  EXPECT_EQ(image.size(), 18u);
  EXPECT_EQ(image.pixels(), 6u);
  EXPECT_EQ(image.ShapeString(), "2x3x3");
}

TEST(Image, RejectsImpossibleShapes) {
  EXPECT_THROW(Image(-1, 3, 1), std::invalid_argument);
  EXPECT_THROW(Image(2, 3, 0), std::invalid_argument);
  EXPECT_THROW(Image(2, 3, 5), std::invalid_argument);
}

TEST(SensorKind, NamesRoundTrip) {
  for (SensorKind kind : {SensorKind::kSoftBubble, SensorKind::kGelSlim}) {
    SensorKind parsed;
    ASSERT_TRUE(SensorKindFromString(ToString(kind), &parsed));
    EXPECT_EQ(parsed, kind);
  }
  SensorKind untouched = SensorKind::kGelSlim;
  EXPECT_FALSE(SensorKindFromString("digit", &untouched));
  EXPECT_EQ(untouched, SensorKind::kGelSlim);
  EXPECT_EQ(SensorChannels(SensorKind::kSoftBubble), 1);
  EXPECT_EQ(SensorChannels(SensorKind::kGelSlim), 3);
}

}  // namespace
}  // namespace tactfunc
