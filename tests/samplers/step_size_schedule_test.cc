// Copyright 2026 The tactfunc Authors.
#include "samplers/step_size_schedule.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "gtest/gtest.h"

namespace tactfunc {
namespace {

TEST(StepSizeSchedule, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(StepSizeSchedule::Options().IsValid(&error)) << error;
}

TEST(StepSizeSchedule, ConstantScheduleNeverChanges) {
  StepSizeSchedule::Options options;
  options.initial = 3e-3;
  StepSizeSchedule schedule(options);
  EXPECT_EQ(schedule(0), 3e-3);
  EXPECT_EQ(schedule(1000000), 3e-3);
}

TEST(StepSizeSchedule, PolynomialScheduleHalvesAtTheDocumentedStep) {
  StepSizeSchedule::Options options;
  options.type = StepSizeSchedule::Type::kPolynomial;
  options.initial = 1.0;
  options.decay_steps = 10.0;
  options.gamma = 1.0;
  StepSizeSchedule schedule(options);
  EXPECT_DOUBLE_EQ(schedule(0), 1.0);
  EXPECT_DOUBLE_EQ(schedule(10), 0.5);
  EXPECT_DOUBLE_EQ(schedule(30), 0.25);
}

TEST(StepSizeSchedule, PolynomialScheduleDecreasesMonotonically) {
  StepSizeSchedule::Options options;
  options.type = StepSizeSchedule::Type::kPolynomial;
  StepSizeSchedule schedule(options);
  for (long t = 0; t < 1000; ++t) EXPECT_LT(schedule(t + 1), schedule(t));
}

TEST(StepSizeSchedule, BadOptionsNameTheField) {
  StepSizeSchedule::Options options;
  options.initial = -1.0;
  std::string error;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("initial"), std::string::npos);
  EXPECT_THROW(StepSizeSchedule{options}, std::invalid_argument);

  options = StepSizeSchedule::Options();
  options.type = StepSizeSchedule::Type::kPolynomial;
  options.gamma = 0.3;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("gamma"), std::string::npos);

  options.gamma = 0.55;
  options.initial = std::nan("");
  EXPECT_FALSE(options.IsValid(&error));
}

}  // namespace
}  // namespace tactfunc
