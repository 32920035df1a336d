#include <dm/core/log.hpp>
#include <dm/network/command.hpp>

#include <openssl/crypto.h>
#include <openssl/rand.h>

#include <array>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <map>
#include <mutex>
#include <optional>
#include <vector>

namespace dm {

namespace {

constexpr char kSessionLabel[] = "DMNM session v1";

std::int64_t steadyNowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

// The raw key of `hex`, or none when authentication is off. Fails when a key
// is required but missing, or malformed.
Result<std::vector<std::byte>> keyFrom(const std::string& hex, bool requireAuth, const char* where) {
  if (hex.empty()) {
    if (requireAuth)
      return fail(
          ErrorCode::InvalidArgument, "no key given but requireAuth is set", std::string(where) + ".keyHex",
          "give a shared secret of 32+ hex digits (`openssl rand -hex 32`), or set requireAuth = false "
          "on a trusted network");
    return std::vector<std::byte>{};
  }
  auto key = parseHexKey(hex);
  if (!key) {
    Error e = key.error();
    e.where = std::string(where) + ".keyHex (" + e.where + ")";
    return e;
  }
  return key;
}

Result<CommandNonce> randomNonce() {
  CommandNonce n{};
  if (RAND_bytes(reinterpret_cast<unsigned char*>(n.data()), static_cast<int>(n.size())) != 1)
    return fail(ErrorCode::Internal, "libcrypto could not produce random bytes", "command channel nonce",
                "check the OpenSSL install and the system's entropy source");
  return n;
}

// One side of a session: signs outgoing messages (any thread, under `mutex`)
// and verifies incoming ones (network thread only).
struct Session {
  std::optional<MessageAuthenticator> in;   // network thread
  SequenceTracker seen;                     // network thread
  mutable std::mutex mutex;                 // guards out, nextSequence, ready
  std::optional<MessageAuthenticator> out;  // signing
  std::uint32_t nextSequence = 1;
  bool ready = false;

  // Both authenticators from one session key.
  Status start(const AuthTag& sessionKey) {
    auto a = MessageAuthenticator::fromKey(sessionKey);
    auto b = MessageAuthenticator::fromKey(sessionKey);
    if (!a) return a.error();
    if (!b) return b.error();
    in.emplace(std::move(*a));
    seen.reset();
    std::lock_guard lock(mutex);
    out.emplace(std::move(*b));
    return ok();
  }

  // Frames (and, with a key, signs) one message into `wire`.
  Status frame(std::uint16_t type, std::span<const std::byte> payload, bool authenticated,
               const MessageLimits& limits, std::vector<std::byte>& wire) {
    std::lock_guard lock(mutex);
    if (!ready)
      return fail(ErrorCode::Network,
                  "the command channel is not ready (not connected or handshake not done)", "command channel",
                  "wait for waitReady() or the peer's connection");
    const MessageHeader h{.type = type, .sequence = nextSequence++, .timestampNs = steadyNowNs()};
    if (authenticated) return out->sign(h, payload, wire, limits);
    return appendMessage(h, payload, wire, limits);
  }
};

// Atomic counters behind CommandStats, one per refusal reason.
struct CommandCounters {
  std::atomic<std::uint64_t> accepted{0}, handshakes{0};
  std::array<std::atomic<std::uint64_t>, 5> refused{};

  void refuse(CommandRefusal r) { ++refused[static_cast<std::size_t>(r)]; }
  CommandStats snapshot() const {
    auto n = [this](CommandRefusal r) { return refused[static_cast<std::size_t>(r)].load(); };
    CommandStats s;
    s.accepted = accepted;
    s.noTag = n(CommandRefusal::NoTag);
    s.badTag = n(CommandRefusal::BadTag);
    s.replayed = n(CommandRefusal::Replayed);
    s.stale = n(CommandRefusal::Stale);
    s.malformed = n(CommandRefusal::Malformed);
    s.handshakes = handshakes;
    return s;
  }
};

CommandRefusal refusalOf(AuthVerdict v) {
  switch (v) {
    case AuthVerdict::NoTag:
      return CommandRefusal::NoTag;
    case AuthVerdict::Replayed:
      return CommandRefusal::Replayed;
    case AuthVerdict::Stale:
      return CommandRefusal::Stale;
    default:
      return CommandRefusal::BadTag;
  }
}

// Checks one received application message of an established session. On
// success `payload` is what the handler gets; otherwise the refusal.
std::optional<CommandRefusal> admit(Session& s, bool authenticated, const MessageView& m,
                                    std::span<const std::byte>& payload) {
  if (m.header.type > kCommandMaxType) return CommandRefusal::Malformed;
  if (!authenticated) {
    payload = m.payload;
    return std::nullopt;
  }
  const AuthVerdict v = s.in->verify(m, s.seen, payload);
  if (v == AuthVerdict::Accepted) return std::nullopt;
  return refusalOf(v);
}

std::span<const std::byte> bytesOf(const CommandNonce& n) { return {n.data(), n.size()}; }

}  // namespace

const char* toString(CommandRefusal r) noexcept {
  switch (r) {
    case CommandRefusal::NoTag:
      return "not signed";
    case CommandRefusal::BadTag:
      return "bad signature";
    case CommandRefusal::Replayed:
      return "replayed";
    case CommandRefusal::Stale:
      return "stale sequence number";
    case CommandRefusal::Malformed:
      return "malformed";
  }
  return "?";
}

Result<AuthTag> deriveCommandSessionKey(std::span<const std::byte> key, const CommandNonce& serverNonce,
                                        const CommandNonce& clientNonce) {
  std::vector<std::byte> data(sizeof(kSessionLabel) - 1 + 2 * kCommandNonceBytes);
  std::memcpy(data.data(), kSessionLabel, sizeof(kSessionLabel) - 1);
  std::memcpy(data.data() + sizeof(kSessionLabel) - 1, serverNonce.data(), kCommandNonceBytes);
  std::memcpy(data.data() + sizeof(kSessionLabel) - 1 + kCommandNonceBytes, clientNonce.data(),
              kCommandNonceBytes);
  return hmacSha256(key, data);
}

// ---------------------------------------------------------------- server

struct CommandServer::Impl {
  struct Connection {
    SocketAddress peer;
    MessageStreamDecoder decoder;
    CommandNonce serverNonce{};
    Session session;
    explicit Connection(const MessageLimits& limits) : decoder(limits) {}
  };

  std::vector<std::byte> key;  // empty: no authentication
  MessageLimits limits;
  CommandHandler onCommand;
  IoThread* thread = nullptr;
  std::unique_ptr<TcpServer> owned;
  // Published once listen() has the server; a connection accepted before
  // that (the network thread may already run) waits for it in greet().
  std::atomic<TcpServer*> tcp{nullptr};
  CommandCounters counters;
  mutable std::mutex mutex;  // guards connections
  std::map<ConnectionId, std::shared_ptr<Connection>> connections;

  std::weak_ptr<Impl> weakSelf;

  ~Impl() { OPENSSL_cleanse(key.data(), key.size()); }
  bool authenticated() const { return !key.empty(); }

  // Closes connection `id` (network thread; the server exists once bytes flow).
  void drop(ConnectionId id) {
    if (TcpServer* server = tcp.load()) (void)server->disconnect(id);
  }

  std::shared_ptr<Connection> find(ConnectionId id) const {
    std::lock_guard lock(mutex);
    auto it = connections.find(id);
    return it == connections.end() ? nullptr : it->second;
  }

  void refuse(ConnectionId id, const Connection& c, CommandRefusal r, const std::string& detail) {
    counters.refuse(r);
    TcpServer* server = tcp.load();
    log::warn("CommandServer port %u: refused a message from %s (connection %llu): %s%s",
              server != nullptr ? unsigned{server->port()} : 0u, describe(c.peer).c_str(),
              static_cast<unsigned long long>(id), toString(r), detail.c_str());
  }

  void onConnect(ConnectionId id, const SocketAddress& peer) {
    auto c = std::make_shared<Connection>(limits);
    c->peer = peer;
    {
      std::lock_guard lock(mutex);
      connections[id] = c;
    }
    if (!authenticated()) {
      std::lock_guard lock(c->session.mutex);
      c->session.ready = true;
      return;
    }
    auto nonce = randomNonce();
    if (!nonce) {
      log::warn("CommandServer: %s", nonce.error().message().c_str());
      return;  // never greeted: the peer's commands are refused until it leaves
    }
    c->serverNonce = *nonce;
    greet(id, *nonce);
  }

  // Handshake step 1: sends the server's nonce (deferred while listen() has
  // not yet published the TcpServer).
  void greet(ConnectionId id, const CommandNonce& nonce) {
    TcpServer* server = tcp.load();
    if (server == nullptr) {
      thread->post([weak = weakSelf, id, nonce] {
        if (auto self = weak.lock()) self->greet(id, nonce);
      });
      return;
    }
    std::vector<std::byte> hello;
    if (!appendMessage({.type = kCommandHelloType, .timestampNs = steadyNowNs()}, bytesOf(nonce), hello) ||
        !server->send(id, hello)) {
      log::warn("CommandServer: could not greet connection %llu; closing",
                static_cast<unsigned long long>(id));
      (void)server->disconnect(id);
    }
  }

  // Handshake step 2 at the server: derives the session key from the
  // client's nonce and checks the client's signature with it.
  bool finishHandshake(ConnectionId id, Connection& c, const MessageView& m) {
    if (m.header.type != kCommandHelloReplyType || m.payload.size() != kCommandNonceBytes + kAuthTagBytes) {
      refuse(id, c, CommandRefusal::NoTag, " (a command before the handshake); closing");
      return false;
    }
    CommandNonce clientNonce{};
    std::memcpy(clientNonce.data(), m.payload.data(), kCommandNonceBytes);
    auto sessionKey = deriveCommandSessionKey(key, c.serverNonce, clientNonce);
    if (!sessionKey || !c.session.start(*sessionKey)) {
      refuse(id, c, CommandRefusal::BadTag, " (session key could not be set up); closing");
      return false;
    }
    OPENSSL_cleanse(sessionKey->data(), sessionKey->size());
    std::span<const std::byte> payload;
    const AuthVerdict v = c.session.in->verify(m, c.session.seen, payload);
    if (v != AuthVerdict::Accepted) {
      refuse(id, c, refusalOf(v), " (handshake: the client does not hold the key); closing");
      return false;
    }
    ++counters.handshakes;
    std::lock_guard lock(c.session.mutex);
    c.session.ready = true;
    return true;
  }

  void onBytes(ConnectionId id, std::span<const std::byte> bytes) {
    auto c = find(id);
    if (!c) return;
    if (!c->decoder.feed(bytes)) {
      refuse(id, *c, CommandRefusal::Malformed, " (receive buffer full); closing");
      drop(id);
      return;
    }
    while (true) {
      auto next = c->decoder.next();
      if (!next) {
        refuse(id, *c, CommandRefusal::Malformed, ": " + next.error().message() + "; closing");
        drop(id);
        return;
      }
      if (!*next) return;
      const MessageView& m = **next;
      bool ready;
      {
        std::lock_guard lock(c->session.mutex);
        ready = c->session.ready;
      }
      if (!ready) {
        if (!finishHandshake(id, *c, m)) {
          drop(id);
          return;
        }
        continue;
      }
      std::span<const std::byte> payload;
      if (auto refusal = admit(c->session, authenticated(), m, payload)) {
        refuse(id, *c, *refusal, "");
        continue;
      }
      ++counters.accepted;
      if (onCommand) onCommand(Command{id, c->peer, m.header, payload});
    }
  }

  void onDisconnect(ConnectionId id, const Disconnect& /*why*/) {
    std::lock_guard lock(mutex);
    connections.erase(id);
  }
};

CommandServer::CommandServer(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}
CommandServer::~CommandServer() { close(); }

Result<std::unique_ptr<CommandServer>> CommandServer::listen(IoThread& thread, CommandServerOptions options,
                                                             CommandHandler onCommand) {
  auto key = keyFrom(options.keyHex, options.requireAuth, "CommandServerOptions");
  if (!key) return key.error();
  auto impl = std::make_shared<Impl>();
  impl->key = std::move(*key);
  impl->limits = options.limits;
  impl->onCommand = std::move(onCommand);
  impl->thread = &thread;
  impl->weakSelf = impl;
  TcpServerCallbacks callbacks = forwardTcpServerCallbacks(std::weak_ptr<Impl>(impl));

  auto tcp = TcpServer::listen(thread, std::move(options.tcp), std::move(callbacks));
  if (!tcp) return tcp.error();
  impl->owned = std::move(*tcp);
  impl->tcp.store(impl->owned.get());
  return std::unique_ptr<CommandServer>(new CommandServer(std::move(impl)));
}

std::uint16_t CommandServer::port() const noexcept { return impl_->owned->port(); }

Status CommandServer::reply(ConnectionId connection, std::uint16_t type, std::span<const std::byte> payload) {
  if (type > kCommandMaxType)
    return fail(ErrorCode::InvalidArgument, formatString("type 0x%04X is reserved", type),
                "CommandServer::reply", "use types 0 .. 0xFFEF");
  auto c = impl_->find(connection);
  if (!c)
    return fail(ErrorCode::NotFound,
                formatString("no connection %llu", static_cast<unsigned long long>(connection)),
                "CommandServer::reply", "the peer may have disconnected");
  std::vector<std::byte> wire;
  if (Status s = c->session.frame(type, payload, impl_->authenticated(), impl_->limits, wire); !s) return s;
  return impl_->owned->send(connection, wire);
}

CommandStats CommandServer::stats() const {
  CommandStats s = impl_->counters.snapshot();
  s.peersRefused = impl_->owned->serverStats().refused;
  return s;
}

void CommandServer::close() {
  if (impl_ && impl_->owned) impl_->owned->close();
}

// ---------------------------------------------------------------- client

struct CommandClient::Impl {
  std::vector<std::byte> key;
  MessageLimits limits;
  CommandHandler onReply;
  IoThread* thread = nullptr;
  std::weak_ptr<Impl> weakSelf;
  std::unique_ptr<TcpClient> owned;
  std::atomic<TcpClient*> tcp{nullptr};  // published once connect() has the client
  SocketAddress peer;
  CommandCounters counters;
  // network thread
  MessageStreamDecoder decoder;
  Session session;
  mutable std::mutex readyMutex;  // with `readyChanged`, for waitReady()
  std::condition_variable readyChanged;

  explicit Impl(const MessageLimits& l) : limits(l), decoder(l) {}
  ~Impl() { OPENSSL_cleanse(key.data(), key.size()); }
  bool authenticated() const { return !key.empty(); }

  bool ready() const {
    std::lock_guard lock(session.mutex);
    return session.ready;
  }
  void setReady(bool r) {
    {
      std::lock_guard lock(session.mutex);
      session.ready = r;
      if (r) session.nextSequence = 1;
    }
    std::lock_guard lock(readyMutex);
    readyChanged.notify_all();
  }

  void refuse(CommandRefusal r, const std::string& detail) {
    counters.refuse(r);
    log::warn("CommandClient %s: refused a message: %s%s", describe(peer).c_str(), toString(r),
              detail.c_str());
  }

  void onState(ConnectionState state, const std::string& /*detail*/) {
    if (state == ConnectionState::Connected) {
      decoder.reset();
      if (!authenticated()) setReady(true);  // else: wait for the server's hello
    } else {
      setReady(false);
    }
  }

  // Handshake steps 1-2 at the client.
  void answerHello(const MessageView& m) {
    if (m.header.type != kCommandHelloType || m.payload.size() != kCommandNonceBytes) {
      refuse(CommandRefusal::Malformed, " (expected the server's hello); waiting for a valid one");
      return;
    }
    CommandNonce serverNonce{};
    std::memcpy(serverNonce.data(), m.payload.data(), kCommandNonceBytes);
    auto clientNonce = randomNonce();
    if (!clientNonce) {
      log::warn("CommandClient %s: %s", describe(peer).c_str(), clientNonce.error().message().c_str());
      return;
    }
    auto sessionKey = deriveCommandSessionKey(key, serverNonce, *clientNonce);
    if (!sessionKey || !session.start(*sessionKey)) {
      log::warn("CommandClient %s: could not set up the session key", describe(peer).c_str());
      return;
    }
    OPENSSL_cleanse(sessionKey->data(), sessionKey->size());
    std::vector<std::byte> wire;
    Status signedReply = [&] {
      std::lock_guard lock(session.mutex);
      return session.out->sign({.type = kCommandHelloReplyType, .sequence = 0, .timestampNs = steadyNowNs()},
                               bytesOf(*clientNonce), wire, limits);
    }();
    if (!signedReply) {
      log::warn("CommandClient %s: could not sign the hello reply", describe(peer).c_str());
      return;
    }
    sendHelloReply(std::move(wire));
  }

  // Handshake step 2 on the wire (deferred while connect() has not yet
  // published the TcpClient).
  void sendHelloReply(std::vector<std::byte> wire) {
    TcpClient* client = tcp.load();
    if (client == nullptr) {
      thread->post([weak = weakSelf, w = std::move(wire)]() mutable {
        if (auto self = weak.lock()) self->sendHelloReply(std::move(w));
      });
      return;
    }
    if (Status s = client->send(wire); !s) {
      log::warn("CommandClient %s: could not answer the hello: %s", describe(peer).c_str(),
                s.error().message().c_str());
      return;
    }
    ++counters.handshakes;
    setReady(true);
  }

  void onBytes(std::span<const std::byte> bytes) {
    if (!decoder.feed(bytes)) {
      refuse(CommandRefusal::Malformed, " (receive buffer full)");
      decoder.reset();
      return;
    }
    while (true) {
      auto next = decoder.next();
      if (!next) {
        refuse(CommandRefusal::Malformed, ": " + next.error().message());
        decoder.reset();
        return;
      }
      if (!*next) return;
      const MessageView& m = **next;
      if (authenticated() && !ready()) {
        answerHello(m);
        continue;
      }
      std::span<const std::byte> payload;
      if (auto refusal = admit(session, authenticated(), m, payload)) {
        refuse(*refusal, "");
        continue;
      }
      ++counters.accepted;
      if (onReply) onReply(Command{0, peer, m.header, payload});
    }
  }
};

CommandClient::CommandClient(std::shared_ptr<Impl> impl) : impl_(std::move(impl)) {}
CommandClient::~CommandClient() { close(); }

Result<std::unique_ptr<CommandClient>> CommandClient::connect(IoThread& thread, CommandClientOptions options,
                                                              CommandHandler onReply) {
  auto key = keyFrom(options.keyHex, options.requireAuth, "CommandClientOptions");
  if (!key) return key.error();
  auto impl = std::make_shared<Impl>(options.limits);
  impl->key = std::move(*key);
  impl->onReply = std::move(onReply);
  impl->peer = options.tcp.peer;
  impl->thread = &thread;
  impl->weakSelf = impl;
  TcpClientCallbacks callbacks = forwardTcpClientCallbacks(std::weak_ptr<Impl>(impl));

  auto tcp = TcpClient::connect(thread, std::move(options.tcp), std::move(callbacks));
  if (!tcp) return tcp.error();
  impl->owned = std::move(*tcp);
  impl->tcp.store(impl->owned.get());
  return std::unique_ptr<CommandClient>(new CommandClient(std::move(impl)));
}

Status CommandClient::waitReady(std::chrono::milliseconds timeout) const {
  std::unique_lock lock(impl_->readyMutex);
  if (impl_->readyChanged.wait_for(lock, timeout, [this] { return impl_->ready(); })) return ok();
  return fail(ErrorCode::Timeout,
              formatString("not ready after %lld ms (state: %s)", static_cast<long long>(timeout.count()),
                           toString(impl_->owned->state())),
              "CommandClient " + describe(impl_->peer), "check the server, the key and the allow-list");
}

Status CommandClient::send(std::uint16_t type, std::span<const std::byte> payload) {
  if (type > kCommandMaxType)
    return fail(ErrorCode::InvalidArgument, formatString("type 0x%04X is reserved", type),
                "CommandClient::send", "use types 0 .. 0xFFEF");
  std::vector<std::byte> wire;
  if (Status s = impl_->session.frame(type, payload, impl_->authenticated(), impl_->limits, wire); !s)
    return s;
  return impl_->owned->send(wire);
}

CommandStats CommandClient::stats() const { return impl_->counters.snapshot(); }

void CommandClient::close() {
  if (impl_ && impl_->owned) impl_->owned->close();
}

}  // namespace dm
