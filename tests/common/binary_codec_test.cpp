#include "slamd/common/binary_codec.hpp"

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <sstream>
#include <streambuf>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "slamd/common/file_io.hpp"

namespace slamd {
namespace {

std::string bytesOf(std::initializer_list<int> values) {
  std::string bytes;
  for (int v : values) bytes.push_back(static_cast<char>(v));
  return bytes;
}

/// One value of each kind, written the same way whatever the sink.
void writeSample(LittleEndianWriter& out) {
  out.u8(0xab);
  out.u16(0x0102);
  out.u32(0x01020304u);
  out.u64(0x0102030405060708ull);
  out.i32(-2);
  out.i64(-3);
  out.f32(1.0f);
  out.f64(-2.0);
  out.raw("xy", 2);
}

const std::string kSampleBytes =
    bytesOf({0xab, 0x02, 0x01, 0x04, 0x03, 0x02, 0x01, 0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02,
             0x01, 0xfe, 0xff, 0xff, 0xff, 0xfd, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0xff, 0x00,
             0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xc0, 'x',  'y'});

/// A stream buffer whose every write fails, like a full disk.
class FailingBuffer : public std::streambuf {
 protected:
  std::streamsize xsputn(const char*, std::streamsize) override { return 0; }
  int_type overflow(int_type) override { return traits_type::eof(); }
};

TEST(LittleEndianWriter, WritesEachKindLittleEndianWhateverTheHost) {
  std::string bytes;
  LittleEndianWriter out(bytes);
  writeSample(out);
  EXPECT_EQ(bytes, kSampleBytes);
  EXPECT_EQ(out.bytesWritten(), kSampleBytes.size());
}

TEST(LittleEndianWriter, StringVectorAndStreamSinksReceiveTheSameBytes) {
  std::vector<std::uint8_t> vector_bytes;
  {
    LittleEndianWriter out(vector_bytes);
    writeSample(out);
  }
  std::ostringstream stream;
  {
    LittleEndianWriter out(stream);
    writeSample(out);
    EXPECT_TRUE(out.flush());
  }
  EXPECT_EQ(std::string(vector_bytes.begin(), vector_bytes.end()), kSampleBytes);
  EXPECT_EQ(stream.str(), kSampleBytes);
}

TEST(LittleEndianWriter, AStreamSinkIsBufferedUntilFlushOrDestruction) {
  std::ostringstream stream;
  {
    LittleEndianWriter out(stream);
    out.u32(7);
    EXPECT_TRUE(stream.str().empty());
    EXPECT_TRUE(out.flush());
    EXPECT_EQ(stream.str().size(), 4u);
    out.u32(8);
  }
  EXPECT_EQ(stream.str(), bytesOf({7, 0, 0, 0, 8, 0, 0, 0}));
}

TEST(LittleEndianWriter, AStreamSinkWritesOutLargeBlocksInOrder) {
  std::ostringstream stream;
  const std::string block(LittleEndianWriter::kStreamBufferBytes + 5, 'b');
  LittleEndianWriter out(stream);
  out.u8('a');
  out.raw(block.data(), block.size());  // goes straight out, after the pending 'a'
  EXPECT_EQ(stream.str().size(), 1 + block.size());
  out.u8('c');
  for (std::size_t i = 0; i < LittleEndianWriter::kStreamBufferBytes; ++i) out.u8('d');
  // The buffer went out once it was full: at most one value is pending.
  EXPECT_GE(stream.str().size(), 1 + block.size() + LittleEndianWriter::kStreamBufferBytes);
  ASSERT_TRUE(out.flush());
  EXPECT_EQ(stream.str(),
            "a" + block + "c" + std::string(LittleEndianWriter::kStreamBufferBytes, 'd'));
}

TEST(LittleEndianWriter, FlushReportsAFailedStreamEvenAfterItRecovers) {
  FailingBuffer failing;
  std::ostream stream(&failing);
  LittleEndianWriter out(stream);
  out.u64(1);
  EXPECT_FALSE(out.flush());
  stream.clear();
  out.u64(2);
  EXPECT_FALSE(out.flush());  // sticky: the first write was lost
  std::string bytes;
  LittleEndianWriter memory(bytes);
  EXPECT_TRUE(memory.flush());
}

TEST(LittleEndianWriter, TheChecksumCoversTheBytesFromStartChecksumOn) {
  std::string bytes;
  LittleEndianWriter out(bytes);
  out.raw("MAGIC", 5);
  EXPECT_EQ(out.checksum(), kFnv1a64Basis);
  out.startChecksum();
  writeSample(out);
  EXPECT_EQ(out.checksum(), fnv1a64(bytes.data() + 5, bytes.size() - 5));
  // Continuing from a seed chains like fnv1a64 itself.
  std::string more;
  LittleEndianWriter next(more);
  next.startChecksum(out.checksum());
  next.u32(42);
  EXPECT_EQ(next.checksum(), fnv1a64((bytes + more).data() + 5, bytes.size() - 5 + 4));
}

TEST(LittleEndianReader, ReadsBackEveryValueFromMemoryAndFromAStream) {
  std::mt19937 rng(42);
  std::uniform_int_distribution<std::uint64_t> any;
  const float kFloats[] = {0.0f,
                           -0.0f,
                           std::numeric_limits<float>::denorm_min(),
                           std::numeric_limits<float>::infinity(),
                           -3.0e38f,
                           std::numeric_limits<float>::quiet_NaN()};
  const double kDoubles[] = {-0.0, std::numeric_limits<double>::denorm_min(), 1e308,
                             -std::numeric_limits<double>::infinity(),
                             std::numeric_limits<double>::quiet_NaN()};
  std::vector<std::uint64_t> words(50);
  for (std::uint64_t& w : words) w = any(rng);
  std::string bytes;
  LittleEndianWriter out(bytes);
  for (std::uint64_t w : words) {
    out.u8(static_cast<std::uint8_t>(w));
    out.u16(static_cast<std::uint16_t>(w));
    out.u32(static_cast<std::uint32_t>(w));
    out.u64(w);
    out.i32(static_cast<std::int32_t>(w));
    out.i64(static_cast<std::int64_t>(w));
  }
  for (float f : kFloats) out.f32(f);
  for (double d : kDoubles) out.f64(d);

  const auto check = [&](LittleEndianReader& in) {
    for (std::uint64_t w : words) {
      EXPECT_EQ(in.u8(), static_cast<std::uint8_t>(w));
      EXPECT_EQ(in.u16(), static_cast<std::uint16_t>(w));
      EXPECT_EQ(in.u32(), static_cast<std::uint32_t>(w));
      EXPECT_EQ(in.u64(), w);
      EXPECT_EQ(in.i32(), static_cast<std::int32_t>(w));
      EXPECT_EQ(in.i64(), static_cast<std::int64_t>(w));
    }
    for (float f : kFloats) {
      const float read = in.f32();
      EXPECT_EQ(std::memcmp(&read, &f, sizeof(f)), 0) << f;  // bit for bit (-0.0, NaN)
    }
    for (double d : kDoubles) {
      const double read = in.f64();
      EXPECT_EQ(std::memcmp(&read, &d, sizeof(d)), 0) << d;
    }
    EXPECT_EQ(in.remaining(), 0u);
    EXPECT_EQ(in.position(), bytes.size());
  };
  LittleEndianReader memory(bytes);
  check(memory);
  std::istringstream stream(bytes);
  LittleEndianReader streamed(stream, bytes.size());
  check(streamed);
}

TEST(LittleEndianReader, AReadPastTheEndThrowsNamingWhereAndMovesNothing) {
  const std::string bytes = bytesOf({1, 2, 3});
  LittleEndianReader in(bytes);
  in.setWhere("edge 2 of 6");
  try {
    in.u32();
    ADD_FAILURE() << "read 4 bytes of 3";
  } catch (const TruncatedBinaryError& e) {
    EXPECT_STREQ(e.what(), "truncated (edge 2 of 6)");
    EXPECT_EQ(e.where(), "edge 2 of 6");
  }
  EXPECT_EQ(in.position(), 0u);
  EXPECT_EQ(in.u16(), 0x0201);
  in.setWhere("");
  try {
    in.truncated();
  } catch (const TruncatedBinaryError& e) {
    EXPECT_STREQ(e.what(), "truncated");
  }
  EXPECT_THROW(in.u16(), TruncatedBinaryError);
  EXPECT_EQ(in.u8(), 3);
  EXPECT_THROW(in.u8(), TruncatedBinaryError);
}

TEST(LittleEndianReader, AStreamIsReadNoFurtherThanAsked) {
  std::istringstream stream(bytesOf({1, 0, 0, 0, 2, 0, 0, 0, 9}));
  LittleEndianReader in(stream, 8);  // the ninth byte is not the reader's
  EXPECT_EQ(in.u32(), 1u);
  EXPECT_EQ(stream.tellg(), 4);
  EXPECT_EQ(in.u32(), 2u);
  // Refused by the size, before the stream is touched.
  EXPECT_THROW(in.u8(), TruncatedBinaryError);
  EXPECT_EQ(stream.get(), 9);
}

TEST(LittleEndianReader, AStreamShorterThanItsSizeOrOfUnknownSizeEndsWithATruncation) {
  std::istringstream shrunk(bytesOf({1, 2, 3}));
  LittleEndianReader in(shrunk, 100);  // a file that shrank since its size was taken
  in.setWhere("points");
  EXPECT_THROW(in.u32(), TruncatedBinaryError);

  std::istringstream unknown(bytesOf({5, 0, 6}));
  LittleEndianReader open_ended(unknown);
  EXPECT_EQ(open_ended.size(), LittleEndianReader::kUnknownSize);
  EXPECT_EQ(open_ended.u16(), 5u);
  EXPECT_THROW(open_ended.u16(), TruncatedBinaryError);
}

TEST(LittleEndianReader, FitsChecksCountsWithoutOverflowing) {
  const std::string bytes(100, '\0');
  LittleEndianReader in(bytes);
  EXPECT_TRUE(in.fits(10, 10));
  EXPECT_FALSE(in.fits(11, 10));
  EXPECT_TRUE(in.fits(9, 10, 10));   // nine items, then 10 reserved bytes
  EXPECT_FALSE(in.fits(10, 10, 1));  // the reserved byte does not fit after ten items
  EXPECT_FALSE(in.fits(1, 1, 200));  // more reserved than remains
  EXPECT_TRUE(in.fits(0, 1, 100));
  EXPECT_FALSE(in.fits(std::numeric_limits<std::uint64_t>::max(), 16));
  EXPECT_TRUE(in.fits(std::numeric_limits<std::uint64_t>::max(), 0));
}

TEST(LittleEndianReader, TheChecksumMatchesTheWritersAndFnv1a64) {
  std::string bytes;
  LittleEndianWriter out(bytes);
  out.raw("HEAD", 4);
  out.startChecksum();
  writeSample(out);
  for (int streamed = 0; streamed < 2; ++streamed) {
    std::istringstream stream(bytes);
    LittleEndianReader memory(bytes);
    LittleEndianReader from_stream(stream, bytes.size());
    LittleEndianReader& in = streamed ? from_stream : memory;
    char head[4];
    in.raw(head, sizeof(head));
    in.startChecksum();
    EXPECT_EQ(in.checksum(), kFnv1a64Basis);
    in.u8();
    in.u16();
    in.u32();
    in.u64();
    in.i32();
    in.i64();
    in.f32();
    in.f64();
    char tail[2];
    in.raw(tail, sizeof(tail));
    EXPECT_EQ(in.checksum(), out.checksum());
    EXPECT_EQ(in.checksum(), fnv1a64(bytes.data() + 4, bytes.size() - 4));
  }
}

TEST(LittleEndianReader, F32sReadsBulkFloatsAndRefusesAnAbsurdCount) {
  std::string bytes;
  LittleEndianWriter out(bytes);
  std::vector<float> values(1000);
  std::mt19937 rng(42);
  std::normal_distribution<float> noise(0.0f, 10.0f);
  for (float& v : values) {
    v = noise(rng);
    out.f32(v);
  }
  LittleEndianReader in(bytes);
  std::vector<float> read(values.size());
  in.f32s(read.data(), read.size());
  EXPECT_EQ(read, values);
  LittleEndianReader again(bytes);
  again.setWhere("points");
  EXPECT_THROW(again.f32s(read.data(), std::numeric_limits<std::size_t>::max() / 2),
               TruncatedBinaryError);
  EXPECT_THROW(again.f32s(read.data(), values.size() + 1), TruncatedBinaryError);
  EXPECT_EQ(again.position(), 0u);
}

TEST(BinaryPose, APoseIsTwelveDoublesRotationRowMajorThenTranslation) {
  SE3 T = SE3::Identity();
  T.linear() = expSO3(Eigen::Vector3d(0.1, -0.2, 0.3));
  T.translation() = Eigen::Vector3d(1.5, -2.5, 3.25);
  std::string bytes;
  LittleEndianWriter out(bytes);
  writePose(out, T);
  ASSERT_EQ(bytes.size(), kBinaryPoseBytes);
  LittleEndianReader fields(bytes);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) EXPECT_EQ(fields.f64(), T.linear()(r, c)) << r << c;
  }
  for (int r = 0; r < 3; ++r) EXPECT_EQ(fields.f64(), T.translation()(r));
  LittleEndianReader in(bytes);
  const SE3 read = readPose(in);
  EXPECT_TRUE(read.matrix() == T.matrix());
}

}  // namespace
}  // namespace slamd
