// Tests of dm::ResourceManager with a toy resource: a text file loaded into
// a struct. Every test writes its files into its own temporary directory.
#include <dm/core/filesystem.hpp>
#include <dm/core/resource.hpp>

#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <fstream>
#include <future>
#include <mutex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core_test_support.hpp"

namespace {

namespace fs = std::filesystem;

struct Text {
  std::string text;
  std::string loader;  // which registered loader produced it
};

// A second resource type over the same files.
struct LineCount {
  std::size_t lines = 0;
};

using dm::test::contains;

dm::Result<std::string> readFile(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  if (!in) return dm::fail(dm::ErrorCode::Io, "cannot open", p.string());
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

class ResourceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("dm_resource_test_" + std::string(info->name()) + "_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  fs::path write(const std::string& name, const std::string& content) {
    const fs::path p = dir_ / name;
    std::ofstream(p, std::ios::binary | std::ios::trunc) << content;
    return p;
  }

  // Registers the text loader for .txt and .md: counts calls, honours the
  // "upper" option, fails on files containing "BROKEN", throws on "THROW".
  void registerText(dm::ResourceManager& rm) {
    auto status = rm.registerLoader<Text>(
        {".txt", ".MD"}, [this](const fs::path& p, const dm::ImportOptions& o) -> dm::Result<Text> {
          calls_.fetch_add(1);
          if (gate_) gate_->wait();
          auto content = readFile(p);
          if (!content) return std::move(content).error();
          if (contains(*content, "BROKEN"))
            return dm::fail(dm::ErrorCode::Parse, "line 1: unexpected token BROKEN", p.string(),
                            "fix the file and reload");
          if (contains(*content, "THROW")) throw std::runtime_error("loader exploded");
          std::string text = *content;
          if (o.getOr("upper", "0") == "1")
            for (char& c : text) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
          return Text{text, "text"};
        });
    ASSERT_TRUE(status) << status.error();
  }

  fs::path dir_;
  std::atomic<int> calls_{0};
  std::shared_future<void>* gate_ = nullptr;  // when set, the loader waits on it
};

TEST_F(ResourceTest, OneInstancePerAsset) {
  dm::ResourceManager rm;
  registerText(rm);
  const fs::path file = write("notes.txt", "hello");
  auto a = rm.load<Text>(file);
  ASSERT_TRUE(a) << a.error();
  EXPECT_EQ(a->get()->text, "hello");
  EXPECT_EQ((*a)->text, "hello");
  EXPECT_EQ(a->version(), 1u);
  EXPECT_EQ(a->path(), fs::weakly_canonical(file));

  // The same file by another spelling of its path is the same instance.
  auto b = rm.load<Text>(dir_ / "sub" / ".." / "." / "notes.txt");
  ASSERT_TRUE(b) << b.error();
  EXPECT_TRUE(*a == *b);
  EXPECT_EQ(a->id(), b->id());
  EXPECT_EQ(a->get().get(), b->get().get());
  EXPECT_EQ(calls_.load(), 1);
  EXPECT_EQ(a->useCount(), 2);

  // Extensions match case-insensitively (".MD" registered, ".Md" on disk).
  auto md = rm.load<Text>(write("README.Md", "# title"));
  ASSERT_TRUE(md) << md.error();
  EXPECT_EQ(md->get()->text, "# title");

  const dm::ResourceStats s = rm.stats();
  EXPECT_EQ(s.liveAssets, 2u);
  EXPECT_EQ(s.loads, 2u);
  EXPECT_EQ(s.cacheHits, 1u);
  EXPECT_EQ(s.failedLoads, 0u);
}

TEST_F(ResourceTest, DifferentOptionsOrTypesGiveDifferentInstances) {
  dm::ResourceManager rm;
  registerText(rm);
  ASSERT_TRUE(rm.registerLoader<LineCount>(
      {".txt"}, [](const fs::path& p, const dm::ImportOptions&) -> dm::Result<LineCount> {
        auto c = readFile(p);
        if (!c) return std::move(c).error();
        return LineCount{static_cast<std::size_t>(std::count(c->begin(), c->end(), '\n'))};
      }));
  const fs::path file = write("poem.txt", "roses\nviolets\n");
  auto plain = rm.load<Text>(file);
  auto upper = rm.load<Text>(file, {{"upper", "1"}});
  ASSERT_TRUE(plain && upper);
  EXPECT_NE(plain->id(), upper->id());
  EXPECT_EQ(plain->get()->text, "roses\nviolets\n");
  EXPECT_EQ(upper->get()->text, "ROSES\nVIOLETS\n");
  EXPECT_EQ(upper->options().getOr("upper", ""), "1");

  // Options are a sorted map: insertion order does not change identity.
  dm::ImportOptions o1;
  o1.set("upper", "1").set("encoding", "utf8");
  dm::ImportOptions o2{{"encoding", "utf8"}, {"upper", "1"}};
  EXPECT_EQ(o1.canonical(), "encoding=utf8;upper=1");
  EXPECT_EQ(o1, o2);
  auto x = rm.load<Text>(file, o1);
  auto y = rm.load<Text>(file, o2);
  ASSERT_TRUE(x && y);
  EXPECT_EQ(x->id(), y->id());
  EXPECT_NE(x->id(), upper->id());  // an extra option is a different asset

  // Escaping keeps canonical strings unambiguous.
  const dm::ImportOptions tricky{{"a=b", "c;d"}};
  const dm::ImportOptions split{{"a", "b=c"}, {"d", ""}};
  EXPECT_EQ(tricky.canonical(), "a\\=b=c\\;d");
  EXPECT_NE(tricky.canonical(), split.canonical());

  // Another type over the same file is another asset.
  auto lines = rm.load<LineCount>(file);
  ASSERT_TRUE(lines) << lines.error();
  EXPECT_EQ(lines->get()->lines, 2u);
  EXPECT_EQ(rm.stats().liveAssets, 4u);
  EXPECT_EQ(calls_.load(), 3);
}

TEST_F(ResourceTest, ReleasingAllHandlesFreesTheAsset) {
  dm::ResourceManager rm;
  registerText(rm);
  const fs::path file = write("a.txt", "alpha");
  std::weak_ptr<const Text> content;
  std::uint64_t firstId = 0;
  {
    auto h1 = rm.load<Text>(file);
    ASSERT_TRUE(h1);
    dm::Handle<Text> h2 = *h1;  // copies share the asset
    EXPECT_EQ(h2.useCount(), 2);
    content = h2.get();
    firstId = h2.id();
    h1->reset();
    EXPECT_FALSE(content.expired());  // h2 still holds it
    EXPECT_EQ(rm.stats().liveAssets, 1u);
  }
  EXPECT_TRUE(content.expired());
  EXPECT_EQ(rm.stats().liveAssets, 0u);

  // Loading again after release runs the loader again: a new instance.
  auto again = rm.load<Text>(file);
  ASSERT_TRUE(again);
  EXPECT_EQ(calls_.load(), 2);
  EXPECT_NE(again->id(), firstId);
  EXPECT_EQ(again->get()->text, "alpha");

  dm::Handle<Text> empty;
  EXPECT_FALSE(empty);
  EXPECT_EQ(empty.id(), 0u);
  EXPECT_EQ(empty.useCount(), 0);
}

TEST_F(ResourceTest, ConcurrentAsyncLoadsRunTheLoaderOnce) {
  dm::ResourceManager rm;
  registerText(rm);
  const fs::path file = write("shared.txt", "shared content");
  std::promise<void> open;
  std::shared_future<void> gate = open.get_future().share();
  gate_ = &gate;

  constexpr int kRequests = 8;
  std::mutex m;
  std::vector<std::uint64_t> ids;
  std::vector<std::string> texts;
  std::atomic<int> callbacks{0};
  for (int i = 0; i < kRequests; ++i) {
    rm.loadAsync<Text>(file, {}, [&](dm::Result<dm::Handle<Text>> r) {
      std::lock_guard lock(m);
      ASSERT_TRUE(r) << r.error();
      ids.push_back(r->id());
      texts.push_back(r->get()->text);
      callbacks.fetch_add(1);
    });
  }
  // Every request after the first joined the pending load.
  EXPECT_EQ(rm.stats().cacheHits, static_cast<std::uint64_t>(kRequests - 1));
  open.set_value();
  rm.waitIdle();
  gate_ = nullptr;

  EXPECT_EQ(calls_.load(), 1);
  EXPECT_EQ(callbacks.load(), kRequests);
  ASSERT_EQ(ids.size(), static_cast<std::size_t>(kRequests));
  EXPECT_TRUE(std::all_of(ids.begin(), ids.end(), [&](std::uint64_t id) { return id == ids[0]; }));
  EXPECT_TRUE(
      std::all_of(texts.begin(), texts.end(), [](const std::string& t) { return t == "shared content"; }));
  EXPECT_EQ(rm.stats().pendingAsync, 0u);
  // The callbacks dropped their handles: the asset is gone.
  EXPECT_EQ(rm.stats().liveAssets, 0u);

  // A cached asset is also delivered asynchronously, without a loader run.
  auto held = rm.load<Text>(file);
  ASSERT_TRUE(held);
  std::promise<std::uint64_t> got;
  rm.loadAsync<Text>(file, {}, [&](dm::Result<dm::Handle<Text>> r) { got.set_value(r ? r->id() : 0); });
  EXPECT_EQ(got.get_future().get(), held->id());
  EXPECT_EQ(calls_.load(), 2);
  rm.waitIdle();
}

TEST_F(ResourceTest, ConcurrentSyncLoadsShareOneLoaderRun) {
  dm::ResourceManager rm;
  registerText(rm);
  const fs::path file = write("sync.txt", "once");
  std::promise<void> open;
  std::shared_future<void> gate = open.get_future().share();
  gate_ = &gate;

  constexpr int kThreads = 4;
  std::vector<std::uint64_t> ids(kThreads, 0);
  std::vector<std::thread> threads;
  for (int i = 0; i < kThreads; ++i) {
    threads.emplace_back([&, i] {
      auto h = rm.load<Text>(file);
      if (h) ids[static_cast<std::size_t>(i)] = h->id();
    });
  }
  // Wait (no timing) until every other thread joined the pending load.
  while (rm.stats().cacheHits < kThreads - 1) std::this_thread::yield();
  open.set_value();
  for (auto& t : threads) t.join();
  gate_ = nullptr;
  EXPECT_EQ(calls_.load(), 1);
  EXPECT_NE(ids[0], 0u);
  for (auto id : ids) EXPECT_EQ(id, ids[0]);
}

TEST_F(ResourceTest, ReloadIsVisibleThroughExistingHandles) {
  dm::ResourceManager rm;
  registerText(rm);
  const fs::path file = write("live.txt", "version one");
  auto h = rm.load<Text>(file);
  ASSERT_TRUE(h);
  dm::Handle<Text> other = *h;
  std::shared_ptr<const Text> before = h->get();

  write("live.txt", "version two");
  ASSERT_TRUE(rm.reload(*h));
  EXPECT_EQ(h->version(), 2u);
  EXPECT_EQ(other.version(), 2u);
  EXPECT_EQ(other.get()->text, "version two");
  EXPECT_EQ((*h)->text, "version two");
  EXPECT_EQ(before->text, "version one");  // a pinned snapshot stays valid
  auto [now, version] = other.snapshot();
  EXPECT_EQ(now->text, "version two");
  EXPECT_EQ(version, 2u);
  // A later load returns the same (reloaded) instance.
  auto again = rm.load<Text>(file);
  ASSERT_TRUE(again);
  EXPECT_EQ(again->id(), h->id());
  EXPECT_EQ(again->version(), 2u);
  EXPECT_EQ(rm.stats().reloads, 1u);
  EXPECT_EQ(calls_.load(), 2);
}

TEST_F(ResourceTest, FailedReloadKeepsTheOldContent) {
  dm::ResourceManager rm;
  registerText(rm);
  const fs::path file = write("fragile.txt", "good data");
  auto h = rm.load<Text>(file);
  ASSERT_TRUE(h);

  write("fragile.txt", "BROKEN data");
  auto bad = rm.reload(*h);
  ASSERT_FALSE(bad);
  EXPECT_EQ(bad.error().code, dm::ErrorCode::Parse);
  EXPECT_HAS(bad.error().what, "unexpected token BROKEN");
  EXPECT_EQ(h->version(), 1u);
  EXPECT_EQ(h->get()->text, "good data");

  write("fragile.txt", "THROW");
  auto threw = rm.reload(*h);
  ASSERT_FALSE(threw);
  EXPECT_EQ(threw.error().code, dm::ErrorCode::Internal);
  EXPECT_HAS(threw.error().what, "loader exploded");
  EXPECT_EQ(h->get()->text, "good data");

  fs::remove(file);
  auto gone = rm.reload(*h);
  ASSERT_FALSE(gone);
  EXPECT_EQ(gone.error().code, dm::ErrorCode::NotFound);
  EXPECT_EQ(gone.error().where, fs::weakly_canonical(file).string());
  EXPECT_EQ(h->get()->text, "good data");
  EXPECT_EQ(h->version(), 1u);

  write("fragile.txt", "fixed");
  ASSERT_TRUE(rm.reload(*h));
  EXPECT_EQ(h->version(), 2u);
  EXPECT_EQ(h->get()->text, "fixed");
  EXPECT_EQ(rm.stats().failedLoads, 3u);

  EXPECT_FALSE(rm.reload(dm::Handle<Text>{}));
}

TEST_F(ResourceTest, UnknownExtensionListsTheRegisteredOnes) {
  dm::ResourceManager rm;
  registerText(rm);
  const fs::path file = write("table.csv", "a,b");
  auto r = rm.load<Text>(file);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, dm::ErrorCode::Unsupported);
  EXPECT_HAS(r.error().what, "'table.csv'");
  EXPECT_HAS(r.error().what, "registered extensions for");
  EXPECT_HAS(r.error().what, "Text");
  EXPECT_HAS(r.error().what, ".md, .txt");
  EXPECT_EQ(r.error().where, fs::weakly_canonical(file).string());
  EXPECT_EQ(calls_.load(), 0);
  EXPECT_EQ(rm.extensions<Text>(), (std::vector<std::string>{".md", ".txt"}));

  auto none = rm.load<LineCount>(write("x.txt", ""));
  ASSERT_FALSE(none);
  EXPECT_HAS(none.error().what, "no loader is registered for");
  EXPECT_HAS(none.error().what, "LineCount");
}

TEST_F(ResourceTest, MissingFileErrorNamesThePath) {
  dm::ResourceManager rm;
  registerText(rm);
  const fs::path file = dir_ / "does_not_exist.txt";
  auto r = rm.load<Text>(file);
  ASSERT_FALSE(r);
  EXPECT_EQ(r.error().code, dm::ErrorCode::NotFound);
  EXPECT_EQ(r.error().where, fs::weakly_canonical(file).string());
  EXPECT_HAS(r.error().message(), file.filename().string());
  EXPECT_EQ(calls_.load(), 0);  // the loader is not asked to open missing files

  std::promise<dm::Error> err;
  rm.loadAsync<Text>(file, {},
                     [&](dm::Result<dm::Handle<Text>> a) { err.set_value(a ? dm::Error{} : a.error()); });
  const dm::Error e = err.get_future().get();
  EXPECT_EQ(e.code, dm::ErrorCode::NotFound);
  EXPECT_EQ(e.where, fs::weakly_canonical(file).string());
  rm.waitIdle();
  EXPECT_EQ(rm.stats().failedLoads, 2u);
  EXPECT_EQ(rm.stats().liveAssets, 0u);
}

TEST_F(ResourceTest, LongestExtensionMatchWins) {
  dm::ResourceManager rm;
  auto tagged = [](std::string tag) {
    return [tag](const fs::path& p, const dm::ImportOptions&) -> dm::Result<Text> {
      auto c = readFile(p);
      if (!c) return std::move(c).error();
      return Text{*c, tag};
    };
  };
  ASSERT_TRUE(rm.registerLoader<Text>({".gz"}, tagged("gzip")));
  ASSERT_TRUE(rm.registerLoader<Text>({".nii", ".nii.gz"}, tagged("nifti")));

  auto volume = rm.load<Text>(write("brain.nii.gz", "v"));
  auto upper = rm.load<Text>(write("HEAD.NII.GZ", "v"));
  auto archive = rm.load<Text>(write("data.gz", "v"));
  auto raw = rm.load<Text>(write("brain.nii", "v"));
  ASSERT_TRUE(volume && upper && archive && raw);
  EXPECT_EQ(volume->get()->loader, "nifti");
  EXPECT_EQ(upper->get()->loader, "nifti");
  EXPECT_EQ(archive->get()->loader, "gzip");
  EXPECT_EQ(raw->get()->loader, "nifti");

  // A file named only by the extension has no stem and is not matched by
  // ".nii.gz" (but ".gz" still matches ".nii.gz" as a name with a stem).
  auto hidden = rm.load<Text>(write(".nii.gz", "v"));
  ASSERT_TRUE(hidden);
  EXPECT_EQ(hidden->get()->loader, "gzip");

  // Registration is checked.
  auto dup = rm.registerLoader<Text>({".NII.GZ"}, tagged("other"));
  ASSERT_FALSE(dup);
  EXPECT_HAS(dup.error().what, "already has a loader for '.nii.gz'");
  EXPECT_FALSE(rm.registerLoader<Text>({"gz"}, tagged("x")));
  EXPECT_FALSE(rm.registerLoader<Text>({".a..b"}, tagged("x")));
  EXPECT_FALSE(rm.registerLoader<Text>({}, tagged("x")));
  EXPECT_FALSE(rm.registerLoader<Text>({".new"}, dm::Loader<Text>{}));
  EXPECT_EQ(rm.extensions<Text>(), (std::vector<std::string>{".gz", ".nii", ".nii.gz"}));
}

}  // namespace

namespace {

// Mount names resolve through the file system: "mricron:ch2.nii.gz" and the
// file's own path are the same asset.
TEST(ResourceMounts, MountNamesAndTheirPathsAreOneAsset) {
  auto located = dm::FileSystem::global().resolve("mricron:ch2.nii.gz");
  if (!located) GTEST_SKIP() << "mricron-data is not installed (scripts/setup.sh installs it)";
  dm::ResourceManager rm;
  std::atomic<int> calls{0};
  fs::path seen;
  ASSERT_TRUE(rm.registerLoader<std::uintmax_t>(
      {".nii.gz"}, [&](const fs::path& p, const dm::ImportOptions&) -> dm::Result<std::uintmax_t> {
        calls.fetch_add(1);
        seen = p;
        return fs::file_size(p);
      }));
  auto byMount = rm.load<std::uintmax_t>("mricron:ch2.nii.gz");
  ASSERT_TRUE(byMount) << byMount.error();
  EXPECT_EQ(*byMount->get(), fs::file_size(*located));
  EXPECT_EQ(seen, fs::weakly_canonical(*located));
  auto byPath = rm.load<std::uintmax_t>(*located);
  ASSERT_TRUE(byPath) << byPath.error();
  EXPECT_EQ(byMount->get(), byPath->get());
  EXPECT_EQ(calls.load(), 1);
  auto missing = rm.load<std::uintmax_t>("mricron:no_such_scan.nii.gz");
  ASSERT_FALSE(missing);
}

}  // namespace
