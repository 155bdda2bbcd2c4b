// Copyright 2026 The tactfunc Authors.
//
// The .npy writer (estimation/data/npy_writer.h): the exact header bytes NumPy writes for
// known shapes, 64-byte alignment, little-endian float32 values, and the errors.
#include "estimation/data/npy_writer.h"

#include <cstring>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;

// The header NumPy's np.save writes for a float32 C-order array whose shape reads
// `shape_text`: the preamble, the dict, spaces up to a multiple of 64 bytes, '\n'.
std::string ExpectedHeader(const std::string& shape_text) {
  std::string dict = "{'descr': '<f4', 'fortran_order': False, 'shape': " + shape_text + ", }";
  while ((10 + dict.size() + 1) % 64 != 0) dict += ' ';
  dict += '\n';
  std::string header("\x93NUMPY\x01\x00", 8);
  header += static_cast<char>(dict.size() & 0xff);
  header += static_cast<char>(dict.size() >> 8);
  return header + dict;
}

TEST(NpyFloat32Header, TwoByThreeIsExactlyNumpysSixtyFourBytes) {
  const std::string header = NpyFloat32Header({2, 3});
  // 10 bytes of preamble + 59 of dict + 1 '\n' = 70, padded to 128: HLEN = 118.
  ASSERT_EQ(header.size(), 128u);
  EXPECT_EQ(header.substr(0, 6), "\x93NUMPY");
  EXPECT_EQ(header[6], '\x01');  // major version
  EXPECT_EQ(header[7], '\x00');  // minor version
  EXPECT_EQ(static_cast<unsigned char>(header[8]), 118);  // HLEN, little-endian
  EXPECT_EQ(static_cast<unsigned char>(header[9]), 0);
  EXPECT_EQ(header.substr(10, 59), "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }");
  EXPECT_EQ(header.substr(69, 58), std::string(58, ' '));
  EXPECT_EQ(header.back(), '\n');
  EXPECT_EQ(header, ExpectedHeader("(2, 3)"));
}

TEST(NpyFloat32Header, OneAndZeroDimensionsAreWrittenAsNumpyWritesThem) {
  EXPECT_EQ(NpyFloat32Header({5}), ExpectedHeader("(5,)"));
  EXPECT_EQ(NpyFloat32Header({}), ExpectedHeader("()"));
  EXPECT_EQ(NpyFloat32Header({0, 70, 88, 1}), ExpectedHeader("(0, 70, 88, 1)"));
}

TEST(NpyFloat32Header, EveryHeaderIsAMultipleOf64Bytes) {
  std::vector<std::int64_t> shape;
  for (int dims = 0; dims < 12; ++dims) {
    const std::string header = NpyFloat32Header(shape);
    EXPECT_EQ(header.size() % 64, 0u) << dims << " dimensions";
    EXPECT_EQ(header.back(), '\n');
    shape.push_back(123456789012LL + dims);
  }
}

TEST(NpyFloat32Header, NegativeDimensionIsRefusedNamingIt) {
  try {
    NpyFloat32Header({2, -1});
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("shape[1]"));
    EXPECT_THAT(e.what(), HasSubstr("-1"));
  }
}

TEST(NpyFloat32Bytes, ValuesFollowTheHeaderAsLittleEndianFloat32InOrder) {
  const std::vector<float> values = {1.0f, -2.0f, 0.5f, 0.0f, 3.25f, -0.125f};
  const std::string bytes = NpyFloat32Bytes({2, 3}, values.data(), values.size());
  ASSERT_EQ(bytes.size(), 128u + 6 * 4);
  EXPECT_EQ(bytes.substr(0, 128), NpyFloat32Header({2, 3}));
  // 1.0f = 0x3f800000: bytes 00 00 80 3f.
  EXPECT_EQ(bytes.substr(128, 4), std::string("\x00\x00\x80\x3f", 4));
  // -2.0f = 0xc0000000.
  EXPECT_EQ(bytes.substr(132, 4), std::string("\x00\x00\x00\xc0", 4));
  for (std::size_t i = 0; i < values.size(); ++i) {
    std::uint32_t bits = 0;
    for (int b = 0; b < 4; ++b) {
      bits |= static_cast<std::uint32_t>(static_cast<unsigned char>(bytes[128 + 4 * i + b]))
              << (8 * b);
    }
    float v;
    std::memcpy(&v, &bits, 4);
    EXPECT_EQ(v, values[i]) << i;
  }
}

TEST(NpyFloat32Bytes, CountThatIsNotTheShapesProductIsRefused) {
  const std::vector<float> values(5, 1.0f);
  try {
    NpyFloat32Bytes({2, 3}, values.data(), values.size());
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("expected 6 values for shape (2, 3), got 5"));
  }
}

TEST(WriteNpyFloat32, WritesTheBytesAndNoTemporaryIsLeft) {
  testing_util::TestDir dir;
  const std::string path = dir.path() + "/a.npy";
  const std::vector<float> values = {1, 2, 3, 4};
  WriteNpyFloat32(path, {4}, values.data(), values.size());
  std::ifstream in(path, std::ios::binary);
  std::stringstream read;
  read << in.rdbuf();
  EXPECT_EQ(read.str(), NpyFloat32Bytes({4}, values.data(), values.size()));
  EXPECT_EQ(testing_util::ListDir(dir.path()), std::vector<std::string>{"a.npy"});
}

}  // namespace
}  // namespace tactfunc
