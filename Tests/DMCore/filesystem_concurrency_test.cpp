// FileStreamReader hands chunks from its reader thread to the caller.
#include <dm/core/filesystem.hpp>

#include <gtest/gtest.h>

#include <fstream>
#include <numeric>
#include <thread>

namespace fs = std::filesystem;

namespace {

TEST(FileStreamReader, StreamsEveryByteInOrder) {
  const fs::path f = fs::temp_directory_path() / ("dm_stream_" + std::to_string(::getpid()) + ".bin");
  std::vector<unsigned char> content(1'000'003);
  for (std::size_t i = 0; i < content.size(); ++i)
    content[i] = static_cast<unsigned char>((i * 131) ^ (i >> 9));
  std::ofstream(f, std::ios::binary)
      .write(reinterpret_cast<const char*>(content.data()), static_cast<std::streamsize>(content.size()));
  auto reader = dm::FileStreamReader::open(f, 64 * 1024, 3);
  ASSERT_TRUE(reader) << reader.error();
  EXPECT_EQ((*reader)->fileSize(), content.size());
  std::vector<unsigned char> got;
  int polls = 0;
  for (;;) {
    // Mix the non-blocking poll with the blocking wait.
    std::optional<dm::Result<dm::FileStreamReader::Chunk>> c;
    if (++polls % 2) c = (*reader)->tryNext();
    if (!c) c = (*reader)->next();
    ASSERT_TRUE(*c) << c->error();
    if ((*c)->data.empty()) break;
    ASSERT_EQ((*c)->offset, got.size());
    for (std::byte b : (*c)->data) got.push_back(static_cast<unsigned char>(b));
  }
  EXPECT_EQ(got, content);
  fs::remove(f);
}

TEST(FileStreamReader, CancelStopsEarlyAndMissingFileFails) {
  const fs::path f = fs::temp_directory_path() / ("dm_stream_c_" + std::to_string(::getpid()) + ".bin");
  std::ofstream(f, std::ios::binary) << std::string(200000, 'z');
  {
    auto reader = dm::FileStreamReader::open(f, 1024, 2);
    ASSERT_TRUE(reader);
    (*reader)->cancel();
  }  // destructor joins
  auto missing = dm::FileStreamReader::open(f.string() + ".missing");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().where.find(".missing"), std::string::npos);
  fs::remove(f);
}

}  // namespace
