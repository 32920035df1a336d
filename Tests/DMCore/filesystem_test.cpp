#include <dm/core/filesystem.hpp>

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>

namespace fs = std::filesystem;

namespace {

fs::path tempDir(const char* name) {
  fs::path d = fs::temp_directory_path() / ("dm_fs_test_" + std::to_string(::getpid()) + "_" + name);
  fs::remove_all(d);
  fs::create_directories(d);
  return d;
}

TEST(FileSystem, ResolvesMountsSearchPathsAndDirectPaths) {
  const fs::path d = tempDir("resolve");
  fs::create_directories(d / "sub");
  std::ofstream(d / "sub" / "a.txt") << "x";
  dm::FileSystem fsys;
  ASSERT_TRUE(fsys.mount("proj", d));
  auto a = fsys.resolve("proj:sub/a.txt");
  ASSERT_TRUE(a) << a.error();
  EXPECT_EQ(*a, d / "sub" / "a.txt");
  fsys.addSearchPath(d / "sub");
  EXPECT_EQ(*fsys.resolve("a.txt"), d / "sub" / "a.txt");
  EXPECT_EQ(*fsys.resolve((d / "sub" / "a.txt").string()), d / "sub" / "a.txt");
  auto missing = fsys.resolve("nothere.txt");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().what.find((d / "sub" / "nothere.txt").string()), std::string::npos)
      << missing.error();
  auto badMount = fsys.resolve("nosuch:x");
  ASSERT_FALSE(badMount);
  EXPECT_NE(badMount.error().hint.find("mricron:"), std::string::npos);
  EXPECT_FALSE(fsys.mount("a", d));
  fs::remove_all(d);
}

TEST(FileSystem, MissingDataPackageIsNamedInTheHint) {
  dm::FileSystem fsys;
  ASSERT_TRUE(fsys.mount("fake", "/nonexistent/dm/data", "some-data-package"));
  auto r = fsys.resolve("fake:file.nii");
  ASSERT_FALSE(r);
  EXPECT_NE(r.error().hint.find("install the Debian package some-data-package"), std::string::npos);
}

TEST(FileSystem, DefaultMountFindsColin27WhenInstalled) {
  auto r = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
  ASSERT_TRUE(r) << r.error() << " — scripts/setup.sh installs mricron-data";
  EXPECT_GT(fs::file_size(*r), 1000000u);
}

TEST(FileSystem, ReadFileAndAtomicWrite) {
  const fs::path d = tempDir("rw");
  const std::string text = "hello, surgeon";
  ASSERT_TRUE(dm::writeFileAtomic(d / "f.bin", text.data(), text.size()));
  auto bytes = dm::readFile(d / "f.bin");
  ASSERT_TRUE(bytes);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(bytes->data()), bytes->size()), text);
  auto tooBig = dm::readFile(d / "f.bin", 4);
  ASSERT_FALSE(tooBig);
  EXPECT_NE(tooBig.error().what.find("file is 14 bytes, more than the limit of 4 bytes"), std::string::npos)
      << tooBig.error();
  // A file's size is judged before a byte is read: a sparse terabyte is
  // refused at once, naming its size.
  {
    std::ofstream(d / "sparse.bin").put('x');
    fs::resize_file(d / "sparse.bin", std::uintmax_t{1} << 40);
    auto huge = dm::readFile(d / "sparse.bin", std::size_t{1} << 30);
    ASSERT_FALSE(huge);
    EXPECT_NE(huge.error().what.find("file is 1099511627776 bytes, more than the limit of 1073741824 bytes"),
              std::string::npos)
        << huge.error();
    fs::remove(d / "sparse.bin");
  }
  // No temporary file left behind.
  int files = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(d)) ++files;
  EXPECT_EQ(files, 1);
  auto missing = dm::readFile(d / "nope");
  ASSERT_FALSE(missing);
  EXPECT_EQ(missing.error().where, (d / "nope").string());
  EXPECT_FALSE(dm::writeFileAtomic(d / "no" / "dir" / "f", "x", 1));
  fs::remove_all(d);
}

}  // namespace
