// Copyright 2026 The tactfunc Authors.
#include "models/core/tensor_file.h"
#include "models/core/atomic_file.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;

TensorFile Example() {
  TensorFile file("model");
  file.set_meta_json(R"({"width": 16, "note": "example"})");
  file.Add("W0", TensorFile::DType::kFloat32, {2, 3}, {1, 2, 3, 4, 5, 6.25});
  file.Add("alpha", TensorFile::DType::kFloat64, {3}, {0.1, 1e-300, -7});
  file.Add("empty", TensorFile::DType::kFloat32, {0, 4}, {});
  return file;
}

std::string TempPath(const std::string& name) {
  return (std::filesystem::path(testing::TempDir()) / name).string();
}

// The files these suites write under testing::TempDir() go to a directory of this test
// process's own (tests/support/unique_temp_dir.cc), never to the shared /tmp itself.
TEST(TensorFile, TestsWriteIntoTheirProcesssOwnTemporaryDirectory) {
  const std::string dir = testing::TempDir();
  EXPECT_NE(dir, "/tmp/");
  EXPECT_THAT(dir, HasSubstr("tactfunc_test_"));
  EXPECT_TRUE(std::filesystem::is_directory(dir)) << dir;
}

TEST(TensorFile, RoundTripsTensorsAndMetaExactly) {
  const TensorFile original = Example();
  const std::string path = TempPath("round_trip.tfm");
  original.Write(path);
  const TensorFile read = TensorFile::Read(path, "model");
  EXPECT_EQ(read.kind(), "model");
  EXPECT_THAT(read.meta_json(), HasSubstr("\"width\":16"));
  ASSERT_EQ(read.tensors().size(), 3u);
  EXPECT_EQ(read.Get("W0", {2, 3}).values, original.Get("W0").values);
  EXPECT_EQ(read.Get("alpha").values, original.Get("alpha").values);
  EXPECT_EQ(read.Get("empty").numel(), 0);
  EXPECT_EQ(read.checksum(), original.checksum());
  EXPECT_NE(read.checksum(), 0u);
}

TEST(TensorFile, Float32TensorsAreRoundedOnAdd) {
  TensorFile file("model");
  file.Add("x", TensorFile::DType::kFloat32, {1}, {0.1});
  EXPECT_EQ(file.Get("x").values[0], static_cast<double>(0.1f));
}

// Bytes a file with n values 7 of `dtype` is smaller than the same as float32.
std::size_t BytesSavedOverFloat32(TensorFile::DType dtype, int n) {
  TensorFile wide("functaset");
  wide.Add("z", TensorFile::DType::kFloat32, {n}, std::vector<double>(n, 7));
  TensorFile narrow("functaset");
  narrow.Add("z", dtype, {n}, std::vector<double>(n, 7));
  return wide.Serialize().size() - narrow.Serialize().size();
}

TEST(TensorFile, Float16TensorsAreRoundedToHalfAndReadBackExactly) {
  TensorFile file("functaset");
  // 1 + 2^-11 is halfway between two halves (ties to even: 1); 65504 is the largest half.
  file.Add("z", TensorFile::DType::kFloat16, {5}, {0.1, -2.5, 1.0 + std::ldexp(1.0, -11), 65504.0, 0.0});
  const std::vector<double>& v = file.Get("z").values;
  EXPECT_NEAR(v[0], 0.1, 0.1 * std::ldexp(1.0, -11));
  EXPECT_NE(v[0], 0.1);
  EXPECT_EQ(v[1], -2.5);
  EXPECT_EQ(v[2], 1.0);
  EXPECT_EQ(v[3], 65504.0);
  EXPECT_EQ(v[4], 0.0);
  const TensorFile read = TensorFile::Parse(file.Serialize(), "half.tfs", "functaset");
  EXPECT_EQ(read.Get("z").dtype, TensorFile::DType::kFloat16);
  EXPECT_EQ(read.Get("z").values, v);
  // Two bytes per value instead of four: the payload shrinks by 800 bytes (the JSON
  // header only by a digit or so of its byte counts).
  const std::size_t saved = BytesSavedOverFloat32(TensorFile::DType::kFloat16, 400);
  EXPECT_GE(saved, 800u);
  EXPECT_LE(saved, 808u);
}

TEST(TensorFile, Uint8TensorsTakeOneByteAndRoundTrip) {
  TensorFile file("functaset");
  file.Add("q", TensorFile::DType::kUint8, {2, 3}, {0, 1, 127, 128, 254, 255});
  const TensorFile read = TensorFile::Parse(file.Serialize(), "codes.tfs", "functaset");
  EXPECT_EQ(read.Get("q", {2, 3}).dtype, TensorFile::DType::kUint8);
  EXPECT_EQ(read.Get("q").values, file.Get("q").values);
  EXPECT_EQ(ElementBytes(TensorFile::DType::kUint8), 1u);
  EXPECT_STREQ(ToString(TensorFile::DType::kUint8), "uint8");
  // One byte per value instead of four: 400 values save 1200 bytes of payload.
  const std::size_t saved = BytesSavedOverFloat32(TensorFile::DType::kUint8, 400);
  EXPECT_GE(saved, 1200u);
  EXPECT_LE(saved, 1208u);
}

TEST(TensorFile, Uint8SerializeRejectsValuesThatAreNotBytes) {
  for (double bad : {-1.0, 256.0, 2.5, std::nan("")}) {
    TensorFile file("functaset");
    file.Add("codes", TensorFile::DType::kUint8, {3}, {0, bad, 1});
    try {
      file.Serialize();
      ADD_FAILURE() << "accepted " << bad;
    } catch (const std::invalid_argument& e) {
      EXPECT_THAT(e.what(), HasSubstr("'codes' element 1"));
      EXPECT_THAT(e.what(), HasSubstr("expected an integer in [0, 255]"));
    }
  }
}

TEST(TensorFile, ChecksumMatchesZlibCrc32) {
  // zlib.crc32(b"123456789") == 0xCBF43926, the standard CRC-32 check value.
  EXPECT_EQ(Crc32("123456789", 9), 0xCBF43926u);
}

TEST(TensorFile, RejectsTruncatedFiles) {
  const std::string bytes = Example().Serialize();
  for (std::size_t keep : {std::size_t{0}, std::size_t{10}, bytes.size() / 2, bytes.size() - 1}) {
    try {
      TensorFile::Parse(bytes.substr(0, keep), "cut.tfm");
      FAIL() << "accepted a file truncated to " << keep << " bytes";
    } catch (const TensorFileError& e) {
      EXPECT_THAT(e.what(), HasSubstr("cut.tfm"));
    }
  }
}

TEST(TensorFile, RejectsACorruptByteAnywhere) {
  const std::string bytes = Example().Serialize();
  for (std::size_t at = 8; at < bytes.size(); at += 7) {
    std::string corrupt = bytes;
    corrupt[at] = static_cast<char>(corrupt[at] ^ 0x5a);
    EXPECT_THROW(TensorFile::Parse(corrupt, "bad.tfm"), TensorFileError) << "byte " << at;
  }
}

TEST(TensorFile, RejectsAnotherVersionWithAClearMessage) {
  std::string bytes = Example().Serialize();
  bytes[8] = 9;  // version 9
  try {
    TensorFile::Parse(bytes, "future.tfm");
    FAIL();
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("version 9"));
  }
}

TEST(TensorFile, RejectsForeignFilesAndTheWrongKind) {
  EXPECT_THROW(TensorFile::Parse(std::string(100, 'x'), "junk"), TensorFileError);
  try {
    TensorFile::Parse(Example().Serialize(), "m.tfm", "functaset");
    FAIL();
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("expected a 'functaset' file"));
  }
  EXPECT_THROW(TensorFile::Read(TempPath("does_not_exist.tfm")), TensorFileError);
}

TEST(TensorFile, GetNamesMissingTensorsAndWrongShapes) {
  const TensorFile file = TensorFile::Parse(Example().Serialize(), "m.tfm");
  try {
    file.Get("nope");
    FAIL();
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("'nope'"));
  }
  try {
    file.Get("W0", {3, 2});
    FAIL();
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("[2, 3]"));
    EXPECT_THAT(e.what(), HasSubstr("[3, 2]"));
  }
}

TEST(TensorFile, AddRejectsMismatchedShapesAndDuplicates) {
  TensorFile file("model");
  EXPECT_THROW(file.Add("a", TensorFile::DType::kFloat32, {2, 2}, {1, 2, 3}),
               std::invalid_argument);
  file.Add("a", TensorFile::DType::kFloat32, {1}, {1});
  EXPECT_THROW(file.Add("a", TensorFile::DType::kFloat32, {1}, {1}), std::invalid_argument);
  EXPECT_THROW(file.set_meta_json("[1, 2]"), TensorFileError);
}

TEST(TensorFile, AtomicWriteReplacesTheWholeFileAndLeavesNoTemporaries) {
  const std::string dir = TempPath("atomic_dir");
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/f.tfm";
  {
    std::ofstream(path) << "old contents that are longer than nothing";
  }
  Example().Write(path);
  EXPECT_NO_THROW(TensorFile::Read(path));
  int entries = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    (void)entry;
    ++entries;
  }
  EXPECT_EQ(entries, 1);
  EXPECT_THROW(WriteFileAtomically(dir + "/missing_subdir/f", "x"), std::runtime_error);
}

// A file with the given JSON header and an 8-byte zero payload, with a valid checksum:
// what a damaged or hostile writer could produce.
std::string FileWithHeader(const std::string& json) {
  std::string out = "TACTFUNC";
  auto put = [&](std::uint64_t value, int bytes) {
    for (int i = 0; i < bytes; ++i) out.push_back(static_cast<char>((value >> (8 * i)) & 0xff));
  };
  put(kTensorFileVersion, 4);
  put(0, 4);
  put(json.size(), 8);
  out += json;
  out += std::string(8, '\0');
  put(Crc32(out.data(), out.size()), 4);
  return out;
}

std::string ParseError(const std::string& bytes) {
  try {
    TensorFile::Parse(bytes, "hostile.tfm");
  } catch (const TensorFileError& e) {
    return e.what();
  }
  return "(no error)";
}

TEST(TensorFile, DeeplyNestedHeaderIsRefusedBeforeAnythingRecurses) {
  // 200000 nested arrays in "meta": the parser would accept them, and dumping or
  // destroying them recursively overflowed the stack.
  const std::string deep = std::string(200000, '[') + std::string(200000, ']');
  const std::string error =
      ParseError(FileWithHeader(R"({"kind": "model", "meta": )" + deep + R"(, "tensors": []})"));
  EXPECT_THAT(error, HasSubstr("hostile.tfm: header: expected JSON nested at most 64 levels"));
  // 64 levels are fine (a user's meta object may nest).
  const std::string ok = std::string(62, '[') + std::string(62, ']');
  TensorFile::Parse(FileWithHeader(R"({"kind": "model", "meta": {"x": )" + ok + R"(}, "tensors": []})"),
                    "ok.tfm");
}

TEST(TensorFile, ShapesAndOffsetsMustBeIntegersInRangeNotCastFloats) {
  const std::string head = R"({"kind": "model", "meta": {}, "tensors": [{"name": "w", "dtype": "uint8", )";
  struct Case {
    std::string tensor;
    const char* piece;
  };
  const Case cases[] = {
      {R"("shape": [2], "offset": -1.0, "bytes": 2)", "tensor 'w': field 'offset': expected an integer in [0, 2^48], got -1.0"},
      {R"("shape": [2], "offset": -1, "bytes": 2)", "field 'offset': expected an integer"},
      {R"("shape": [2], "offset": 1e300, "bytes": 2)", "field 'offset': expected an integer"},
      {R"("shape": [1e21, 64], "offset": 0, "bytes": 2)", "field 'shape': expected integers in [0, 2^48], got 1e+21"},
      {R"("shape": [1.5], "offset": 0, "bytes": 2)", "field 'shape': expected integers"},
      {R"("shape": [-3], "offset": 0, "bytes": 2)", "field 'shape': expected integers"},
      {R"("shape": [18446744073709551615], "offset": 0, "bytes": 2)", "field 'shape': expected integers"},
      {R"("shape": [16777216, 16777216, 16777216], "offset": 0, "bytes": 2)", "holds more than 2^48 elements"},
      {R"("shape": "2", "offset": 0, "bytes": 2)", "field 'shape': expected an array"},
      {R"("shape": [9], "offset": 0, "bytes": 9)", "lies outside the 8-byte payload"},
  };
  for (const Case& c : cases) {
    EXPECT_THAT(ParseError(FileWithHeader(head + c.tensor + "}]}")), HasSubstr(c.piece)) << c.tensor;
  }
  // The largest well-formed tensor still reads.
  const TensorFile read = TensorFile::Parse(
      FileWithHeader(head + R"("shape": [2, 4], "offset": 0, "bytes": 8}]})"), "ok.tfm");
  EXPECT_EQ(read.Get("w", {2, 4}).values.size(), 8u);
}

TEST(TensorFile, ErrorMessagesQuoteAtMost200BytesOfAValue) {
  const std::string huge(10 << 20, 'k');  // a 10 MB "kind"
  const std::string error = ParseError(
      FileWithHeader(R"({"kind": ")" + huge + R"(", "meta": {}, "tensors": []})"));
  (void)error;  // no expected kind: accepted
  try {
    TensorFile::Parse(FileWithHeader(R"({"kind": ")" + huge + R"(", "meta": {}, "tensors": []})"),
                      "big.tfm", "model");
    FAIL();
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("big.tfm: is a 'kkkk"));
    EXPECT_THAT(e.what(), HasSubstr("... (10485760 bytes)"));
    EXPECT_LT(std::string(e.what()).size(), 400u);
  }
  const std::string bad_meta =
      ParseError(FileWithHeader(R"({"kind": "model", "meta": [")" + huge + R"("], "tensors": []})"));
  EXPECT_THAT(bad_meta, HasSubstr("field 'meta': expected a JSON object"));
  EXPECT_LT(bad_meta.size(), 400u);
  const std::string bad_dtype = ParseError(FileWithHeader(
      R"({"kind": "model", "meta": {}, "tensors": [{"name": "w", "dtype": ")" + huge +
      R"(", "shape": [1], "offset": 0}]})"));
  EXPECT_THAT(bad_dtype, HasSubstr("expected uint8, float16, float32 or float64"));
  EXPECT_LT(bad_dtype.size(), 400u);
  // A JSON syntax error deep in a long string: the parser's message is cut too.
  const std::string bad_json = ParseError(FileWithHeader(R"({"kind": ")" + huge + "\x01\"}"));
  EXPECT_THAT(bad_json, HasSubstr("header is not valid JSON"));
  EXPECT_LT(bad_json.size(), 400u);
}

TEST(TensorFile, CheckFormatQuotesTheExpectedFormat) {
  TensorFile file("model");
  file.set_meta_json(R"({"version": 1})");
  const TensorFile read = TensorFile::Parse(file.Serialize(), "m.tfm");
  try {
    read.CheckFormat("tactfunc-model", 1);
    FAIL();
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("field 'format' is missing; expected \"tactfunc-model\""));
  }
}

}  // namespace
}  // namespace tactfunc
