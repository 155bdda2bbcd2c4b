// Copyright 2026 The tactfunc Authors.
//
// TableEvaluation's own checks; its figures are checked end to end by
// tests/apps/eval_cli_test.cc (the `eval` command prints and writes them).
#include "estimation/evaluation/table_evaluation.h"

#include <stdexcept>
#include <string>

#include "gtest/gtest.h"

namespace tactfunc {
namespace {

TEST(TableEvaluationOptions, DefaultsAreValidAndBadValuesNameTheField) {
  std::string error;
  EXPECT_TRUE(TableEvaluation::Options().IsValid(&error)) << error;
  TableEvaluation::Options options;
  options.threads = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("threads"), std::string::npos) << error;
  options = TableEvaluation::Options();
  options.knn_k = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("knn_k"), std::string::npos) << error;
  options = TableEvaluation::Options();
  options.jpeg_curve_qualities = {10, 101};
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("jpeg_curve_qualities"), std::string::npos) << error;
}

TEST(TableEvaluation, MissingInputsAreRejectedBeforeAnyWork) {
  EXPECT_THROW(TableEvaluation::Evaluate(TableEvaluation::Inputs(), TableEvaluation::Options(),
                                         nullptr),
               std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
