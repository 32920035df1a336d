// igtl_engine.cpp — a scene's OpenIGTLink server: tool, handle, force,
// bodies and frames published at the engine's rate (igtl_engine.hpp).
#include "igtl_engine.hpp"

#include <dm/core/log.hpp>
#include <dm/io/scene_file.hpp>
#include <dm/network/drivers.hpp>
#include <dm/network/igtl_session.hpp>
#include <dm/network/io_thread.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <thread>

#include "frame_slot.hpp"

namespace dm {

namespace {

// How long shutdown waits for the clients' queues to empty (the last
// messages of a lockstep run, which ends faster than a socket drains).
constexpr std::chrono::milliseconds kDrain{2000};

// An RGBA frame as the RGB image OpenIGTLink clients show (3D Slicer takes
// 3-component 8-bit images as colour).
Result<Image> toRgb(const Image& rgba) {
  auto rgb = Image::create(rgba.width(), rgba.height(), 3, PixelType::U8);
  if (!rgb) return rgb.error();
  for (int y = 0; y < rgba.height(); ++y) {
    const std::byte* in = rgba.row(y);
    std::byte* out = rgb->row(y);
    for (int x = 0; x < rgba.width(); ++x)
      for (int c = 0; c < 3; ++c)
        out[3 * static_cast<std::size_t>(x) + static_cast<std::size_t>(c)] =
            in[4 * static_cast<std::size_t>(x) + static_cast<std::size_t>(c)];
  }
  return rgb;
}

class IgtlEngine final : public Engine, public IgtlEngineHandle {
 public:
  IgtlEngine(const SceneIgtlEngine& settings, IgtlFeed feed) : settings_(settings), feed_(std::move(feed)) {}
  ~IgtlEngine() override { close(); }

  std::string_view name() const noexcept override { return "igtl"; }

  bool tick(const TickInfo& info) noexcept override {
    try {
      return publishAll(time_.seconds(info));
    } catch (const std::exception& e) {
      error_ = fail(ErrorCode::Internal, e.what(), "engines/igtl");
      return false;
    }
  }

  Status shutdown() override {
    // Let what was queued reach the clients, then close.
    const auto until = std::chrono::steady_clock::now() + kDrain;
    while (server_ && server_->queuedBytes() > 0 && std::chrono::steady_clock::now() < until)
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    close();
    return ok();
  }

  Error error() const override { return error_; }
  std::shared_ptr<Engine> engine() override { return self_.lock(); }
  std::uint16_t port() const override { return port_; }

  Status waitForClients(const std::atomic<bool>* stop) override {
    const auto start = std::chrono::steady_clock::now();
    const auto limit = std::chrono::duration<double>(settings_.waitTimeout);
    while (server_->connections().size() < static_cast<std::size_t>(settings_.waitForClients)) {
      if (stop != nullptr && stop->load()) return ok();
      if (std::chrono::steady_clock::now() - start > limit)
        return fail(ErrorCode::Timeout,
                    formatString("%zu of %d OpenIGTLink clients connected to port %u in %g s",
                                 server_->connections().size(), settings_.waitForClients, unsigned{port_},
                                 settings_.waitTimeout),
                    "engines/igtl/wait_for_clients",
                    "connect them (e.g. 3D Slicer's OpenIGTLinkIF) or lower it");
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return ok();
  }

  nlohmann::json summary() const override {
    const IgtlStats st = server_ ? server_->stats() : stats_;
    return {{"port", port_},
            {"clients", clientsSeen_.load()},
            {"published", {{"transform", transforms_}, {"sensor", sensors_}, {"image", images_}}},
            {"messages_out", st.messagesOut},
            {"messages_in", st.messagesIn},
            {"queries_answered", st.queriesAnswered},
            {"send_failures", st.sendFailures},
            {"malformed", st.malformed}};
  }

  Status start() {
    auto listen = parseEndpoint(settings_.listen, "engines/igtl/listen", true);
    if (!listen) return listen.error();
    if (auto s = io_.start(); !s) return s.error().within("engines/igtl");
    IgtlServerOptions o;
    o.tcp.local = *listen;
    o.tcp.allow = settings_.allow;
    // One rendered frame (RGB) must fit a client's queue, with room for the
    // poses and a second frame; the smallest queue is the library's 1 MiB.
    o.tcp.sendQueueBytes = std::max<std::size_t>(o.tcp.sendQueueBytes, 2 * frameBytes_ + (64 << 10));
    o.onConnect = [this](ConnectionId, const SocketAddress& peer) {
      clientsSeen_.fetch_add(1, std::memory_order_relaxed);
      log::info("OpenIGTLink client %s connected", describe(peer).c_str());
    };
    auto server = IgtlServer::listen(io_, std::move(o), {});
    if (!server) return server.error().within("engines/igtl/listen");
    server_ = std::move(*server);
    port_ = server_->port();
    log::info("OpenIGTLink server listening on %s:%u", listen->address.c_str(), unsigned{port_});
    return ok();
  }

  std::weak_ptr<IgtlEngine> self_;
  std::size_t frameBytes_ = 0;  // of one RGB frame, 0 without frames

 private:
  bool publishAll(double t) {
    Isometry3 tool, handle;
    Vec3 force;
    double hapticT = 0.0;
    if (feed_.haptics && feed_.haptics(tool, handle, force, hapticT)) {
      const igtl::Envelope at = stamped(hapticT);  // the haptic tick's own time
      if (!settings_.tool.empty() &&
          !publish(igtl::encodeTransform(named(at, settings_.tool), tool), transforms_))
        return false;
      if (!settings_.handle.empty() &&
          !publish(igtl::encodeTransform(named(at, settings_.handle), handle), transforms_))
        return false;
      if (!settings_.force.empty() &&
          !publish(igtl::encodeSensor(named(at, settings_.force),
                                      {.unit = igtl::kUnitNewton, .data = {force.x(), force.y(), force.z()}}),
                   sensors_))
        return false;
    }
    // The bodies' newest poses, stamped with this tick's time.
    if (settings_.bodies && feed_.bodyPoses && feed_.bodyPoses(poses_))
      for (std::size_t i = 0; i < poses_.size() && i < feed_.bodies.size(); ++i)
        if (!publish(igtl::encodeTransform(named(stamped(t), feed_.bodies[i]), poses_[i]), transforms_))
          return false;
    double frameT = 0.0;
    if (!settings_.image.empty() && feed_.frames && feed_.frames->takeIfNewer(frameSeen_, frame_, frameT)) {
      auto rgb = toRgb(frame_);
      if (!rgb) {
        error_ = rgb.error().within("engines/igtl/publish/image");
        return false;
      }
      if (!publish(igtl::encodeImage(named(stamped(frameT), settings_.image), *rgb), images_)) return false;
    }
    return true;
  }

  // Version-1 messages (what every client reads) stamped with scene time.
  static igtl::Envelope stamped(double t) {
    return {.version = 1, .timestamp = igtl::timestampFromNanos(std::llround(t * 1e9))};
  }

  static igtl::Envelope named(const igtl::Envelope& base, const std::string& device) {
    igtl::Envelope e = base;
    e.deviceName = device;
    return e;
  }

  // Stores and sends one encoded message; a client that cannot take it is
  // counted by the server, not an error of the run.
  bool publish(const Result<std::vector<std::byte>>& message, std::uint64_t& counter) {
    if (!message) {
      error_ = message.error().within("engines/igtl");
      return false;
    }
    auto f = server_->publish(*message, IgtlPublishTo::Everyone);
    if (!f) {
      error_ = f.error().within("engines/igtl");
      return false;
    }
    ++counter;
    return true;
  }

  void close() {
    if (server_) {
      stats_ = server_->stats();
      server_->close();
      server_.reset();
    }
    (void)io_.stop();
  }

  SceneIgtlEngine settings_;
  IgtlFeed feed_;
  IoThread io_{"dm-igtl"};
  std::unique_ptr<IgtlServer> server_;
  std::uint16_t port_ = 0;
  IgtlStats stats_;  // once closed
  std::atomic<std::uint64_t> clientsSeen_{0};
  std::uint64_t transforms_ = 0, sensors_ = 0, images_ = 0;
  std::vector<Isometry3> poses_;
  std::uint64_t frameSeen_ = 0;
  Image frame_;
  Error error_;
  TickTime time_;
};

}  // namespace

Result<std::shared_ptr<IgtlEngineHandle>> makeIgtlEngine(const SceneIgtlEngine& settings, IgtlFeed feed,
                                                         std::size_t frameBytes) {
  auto e = std::make_shared<IgtlEngine>(settings, std::move(feed));
  e->self_ = e;
  e->frameBytes_ = frameBytes;
  if (auto s = e->start(); !s) return s.error();
  return std::shared_ptr<IgtlEngineHandle>(e);
}

}  // namespace dm
