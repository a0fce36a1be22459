#include "moverl_tcpros/server.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>

#include <ros/console.h>
#include <ros/init.h>
#include <ros/network.h>
#include <ros/this_node.h>

#include "moverl_tcpros/master.h"

namespace moverl_tcpros {
namespace {

/// A bound on reading a request or a header once its first byte is there, and on writing an answer: a peer that
/// stops half-way through a message is dropped instead of holding a server thread.
constexpr double kMessageTimeout = 5.0;
/// How long a refused client's header is waited for (and dropped) before its connection is closed, and how many
/// refused connections wait at once (the oldest is closed first).
constexpr double kRefusedLinger = 1.0;
constexpr std::size_t kMaxRefused = 64;

/// A socket listening on the loopback or the wildcard address of `family` at `port` (0: any). -1 with errno set.
int listenOn(int family, bool loopback, std::uint16_t port) {
  const int fd = ::socket(family, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd < 0) return -1;
  int rc;
  if (family == AF_INET6) {
    int one = 1;  // IPv6 only: IPv4 clients have a socket of their own
    setsockopt(fd, IPPROTO_IPV6, IPV6_V6ONLY, &one, sizeof(one));
    sockaddr_in6 a{};
    a.sin6_family = AF_INET6;
    a.sin6_port = htons(port);
    a.sin6_addr = loopback ? in6addr_loopback : in6addr_any;
    rc = ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a));
  } else {
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_port = htons(port);
    a.sin_addr.s_addr = htonl(loopback ? INADDR_LOOPBACK : INADDR_ANY);
    rc = ::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a));
  }
  if (rc < 0 || ::listen(fd, 64) < 0) {
    const int saved = errno;
    ::close(fd);
    errno = saved;
    return -1;
  }
  return fd;
}

std::uint16_t localPort(int fd) {
  sockaddr_storage a{};
  socklen_t len = sizeof(a);
  if (getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) < 0) return 0;
  return ntohs(a.ss_family == AF_INET6 ? reinterpret_cast<sockaddr_in6*>(&a)->sin6_port
                                       : reinterpret_cast<sockaddr_in*>(&a)->sin_port);
}

int millisecondsUntil(SteadyClock::time_point t) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(t - SteadyClock::now()).count();
  return left <= 0 ? 0 : static_cast<int>(std::min<long long>(left + 1, 1 << 30));
}

}  // namespace

// ----------------------------------------------------------------------------------------------------- set-up, stop
ServiceServer::ServiceServer(std::string resolved_name, Type type, RawHandler handler, ServerOptions options)
    : name_(std::move(resolved_name)),
      type_(std::move(type)),
      handler_(std::move(handler)),
      options_(std::move(options)) {
  if (options_.max_clients == 0) throw std::invalid_argument("service " + name_ + ": max_clients must be at least 1");
  if (!ros::isStarted()) {
    throw std::runtime_error("service " + name_ + ": the node is not started (create a ros::NodeHandle first)");
  }
  // registerService wants the node's XML-RPC URI (caller_api). roscpp has no public accessor for it; the master has
  // it, since ros::start() registers the node's ~get_loggers and ~set_logger_level services before it returns.
  const SteadyClock::time_point deadline = after(options_.master_timeout);
  std::string caller_api, error;
  if (!lookupNode(ros::this_node::getName(), deadline, &caller_api, &error)) {
    throw std::runtime_error("service " + name_ + ": the master does not know this node: " + error);
  }
  if (::pipe2(wake_, O_CLOEXEC) < 0) throw std::runtime_error("service " + name_ + ": " + std::strerror(errno));
  try {
    listen(options_.host.empty() ? ros::network::getHost() : options_.host);
  } catch (...) {
    ::close(wake_[0]);
    ::close(wake_[1]);
    throw;
  }
  accept_thread_ = std::thread([this] { acceptLoop(); });
  XmlRpc::XmlRpcValue params, unused;
  params[0] = ros::this_node::getName();
  params[1] = name_;
  params[2] = uri_;
  params[3] = caller_api;
  if (!callMaster("registerService", params, &unused, deadline, &error)) {
    stopAndJoin();
    throw std::runtime_error("cannot register service " + name_ + " with the master: " + error);
  }
}

ServiceServer::~ServiceServer() {
  std::string error;
  if (!unregister(&error)) ROS_WARN("service %s: %s", name_.c_str(), error.c_str());
  stopAndJoin();
}

bool ServiceServer::unregister(std::string* error) {
  XmlRpc::XmlRpcValue params, count;
  params[0] = ros::this_node::getName();
  params[1] = name_;
  params[2] = uri_;
  return callMaster("unregisterService", params, &count, after(options_.master_timeout), error);
}

void ServiceServer::listen(const std::string& host) {
  // Which address families the advertised host resolves to, and whether only to loopback addresses in each.
  bool v4 = false, v6 = false, v4_loopback = true, v6_loopback = true;
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  if (getaddrinfo(host.c_str(), nullptr, &hints, &res) == 0) {
    for (const addrinfo* ai = res; ai != nullptr; ai = ai->ai_next) {
      if (ai->ai_family == AF_INET) {
        v4 = true;
        const auto* a = reinterpret_cast<const sockaddr_in*>(ai->ai_addr);
        v4_loopback = v4_loopback && (ntohl(a->sin_addr.s_addr) >> 24) == 127;
      } else if (ai->ai_family == AF_INET6) {
        v6 = true;
        const auto* a = reinterpret_cast<const sockaddr_in6*>(ai->ai_addr);
        v6_loopback = v6_loopback && IN6_IS_ADDR_LOOPBACK(&a->sin6_addr);
      }
    }
    freeaddrinfo(res);
  }
  if (!v4 && !v6) {  // as roscpp: clients elsewhere may know the name
    ROS_WARN("service %s: host %s does not resolve here; listening on every IPv4 address", name_.c_str(), host.c_str());
    v4 = true;
    v4_loopback = false;
  }
  // One port for every family: the first socket takes one the kernel picks, the other binds the same (retried when
  // that port is taken in the other family).
  std::string why;
  for (int attempt = 0; attempt < 20 && listen_fds_.empty(); ++attempt) {
    std::uint16_t port = 0;
    for (int family : {AF_INET, AF_INET6}) {
      if ((family == AF_INET && !v4) || (family == AF_INET6 && !v6)) continue;
      const int fd = listenOn(family, family == AF_INET ? v4_loopback : v6_loopback, port);
      if (fd < 0) {
        why = std::strerror(errno);
        for (int l : listen_fds_) ::close(l);
        listen_fds_.clear();
        if (port != 0 && errno == EADDRINUSE) break;  // try another port
        throw std::runtime_error("cannot listen for service " + name_ + " (host " + host + "): " + why);
      }
      listen_fds_.push_back(fd);
      if (port == 0) port = localPort(fd);
    }
    if (!listen_fds_.empty()) uri_ = rosrpcUri(host, port);
  }
  if (listen_fds_.empty()) throw std::runtime_error("cannot listen for service " + name_ + ": " + why);
}

void ServiceServer::stopAndJoin() {
  stop_ = true;
  const char b = 0;
  (void)!::write(wake_[1], &b, 1);  // every thread polls the pipe's read end: all wake up and return
  if (accept_thread_.joinable()) accept_thread_.join();
  {
    std::lock_guard<std::mutex> lock(threads_mutex_);
    for (auto& c : threads_) c.thread.join();  // a running handler finishes first (its own deadlines bound it)
    threads_.clear();
  }
  for (int fd : listen_fds_) ::close(fd);
  listen_fds_.clear();
  ::close(wake_[0]);
  ::close(wake_[1]);
}

// ----------------------------------------------------------------------------------------------------------- accept
void ServiceServer::acceptLoop() {
  std::vector<pollfd> fds;
  while (!stop_) {
    fds.clear();
    for (int fd : listen_fds_) fds.push_back({fd, POLLIN, 0});
    fds.push_back({wake_[0], POLLIN, 0});
    int timeout = -1;
    for (const Refused& r : refused_) {
      fds.push_back({r.fd, POLLIN, 0});
      const int ms = millisecondsUntil(r.until);
      timeout = timeout < 0 ? ms : std::min(timeout, ms);
    }
    if (::poll(fds.data(), fds.size(), timeout) < 0) {
      if (errno == EINTR) continue;
      ROS_ERROR("service %s: poll failed: %s", name_.c_str(), std::strerror(errno));
      break;
    }
    if (fds[listen_fds_.size()].revents || stop_) break;
    // Refused clients: drop what they send; close at their end of stream, an error or their time.
    const auto now = SteadyClock::now();
    std::size_t k = listen_fds_.size() + 1;
    for (auto it = refused_.begin(); it != refused_.end(); ++k) {
      bool done = now >= it->until;
      if (fds[k].revents) {
        char scratch[4096];
        const ssize_t n = ::recv(it->fd, scratch, sizeof(scratch), MSG_DONTWAIT);
        done = done || n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK && errno != EINTR);
      }
      if (done) {
        ::close(it->fd);
        it = refused_.erase(it);
      } else {
        ++it;
      }
    }
    for (std::size_t i = 0; i < listen_fds_.size(); ++i) {
      if (fds[i].revents) accept(listen_fds_[i]);
    }
  }
  for (const Refused& r : refused_) ::close(r.fd);
  refused_.clear();
}

void ServiceServer::reapConnections() {
  std::lock_guard<std::mutex> lock(threads_mutex_);
  for (auto it = threads_.begin(); it != threads_.end();) {
    if (it->done->load()) {
      it->thread.join();
      it = threads_.erase(it);
    } else {
      ++it;
    }
  }
}

void ServiceServer::accept(int listen_fd) {
  const int fd = ::accept4(listen_fd, nullptr, nullptr, SOCK_CLOEXEC | SOCK_NONBLOCK);
  if (fd < 0) {
    if (errno == EMFILE || errno == ENFILE || errno == ENOMEM || errno == ENOBUFS) {
      ROS_ERROR_THROTTLE(10.0, "service %s: cannot accept a client: %s", name_.c_str(), std::strerror(errno));
      std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the client stays queued: no busy loop
    }
    return;  // EAGAIN: the client left before it was accepted
  }
  reapConnections();
  if (active_.load() >= options_.max_clients) {
    // Refused: an error header (a fresh socket's buffer takes it at once), then our end of the stream. The client's
    // own header is read and dropped until it closes (acceptLoop), so that it can read ours first.
    const std::vector<std::uint8_t> body =
        encodeHeader({{"error", "service " + name_ + " serves at most " + std::to_string(options_.max_clients) +
                                    " clients at once (ServerOptions::max_clients); try again later"}});
    std::vector<std::uint8_t> out(4);
    const std::uint32_t len = static_cast<std::uint32_t>(body.size());
    std::memcpy(out.data(), &len, 4);
    out.insert(out.end(), body.begin(), body.end());
    (void)!::send(fd, out.data(), out.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
    ::shutdown(fd, SHUT_WR);
    if (refused_.size() >= kMaxRefused) {
      ::close(refused_.front().fd);
      refused_.erase(refused_.begin());
    }
    refused_.push_back({fd, after(kRefusedLinger)});
    ROS_WARN_THROTTLE(10.0, "service %s: refused a client: %zu clients connected (the limit)", name_.c_str(),
                      options_.max_clients);
    return;
  }
  std::lock_guard<std::mutex> lock(threads_mutex_);
  try {
    auto done = std::make_shared<std::atomic<bool>>(false);
    ++active_;
    threads_.push_back(Connection{std::thread([this, fd, done] {
                                    try {
                                      serve(fd);
                                    } catch (const std::exception& e) {  // the connection ends, never the node
                                      ROS_ERROR("service %s: %s", name_.c_str(), e.what());
                                    }
                                    --active_;
                                    *done = true;
                                  }),
                                  done});
  } catch (const std::exception& e) {  // no thread for it: the client is dropped
    --active_;
    ROS_ERROR("service %s: cannot serve a client: %s", name_.c_str(), e.what());
    ::close(fd);
  }
}

// ------------------------------------------------------------------------------------------------------------ serve
void ServiceServer::serve(int fd) {
  Socket socket(fd);
  HeaderFields header;
  std::string error;
  if (!socket.readHeader(&header, after(kMessageTimeout), &error, wake_[0])) {
    if (!stop_ && !socket.timedOut() && !socket.closedByPeer()) {
      socket.writeHeader({{"error", error}}, after(kMessageTimeout));  // a header we cannot read: say so
    }
    return;
  }
  const auto md5 = header.find("md5sum");
  HeaderFields answer = {{"callerid", ros::this_node::getName()},
                         {"md5sum", type_.md5sum},
                         {"type", type_.datatype},
                         {"request_type", type_.request_type},
                         {"response_type", type_.response_type}};
  if (header["service"] != name_) {
    answer = {{"error", "this connection serves " + name_ + ", not '" + header["service"] + "'"}};
  } else if (md5 == header.end()) {
    answer = {{"error", "the connection header has no md5sum"}};
  } else if (md5->second != "*" && md5->second != type_.md5sum) {
    answer = {{"error", "md5sums do not match: [" + md5->second + "] vs. [" + type_.md5sum + "]"}};
  }
  if (!socket.writeHeader(answer, after(kMessageTimeout)) || answer.count("error") || header["probe"] == "1") return;
  const bool persistent = header["persistent"] == "1" || header["persistent"] == "true";  // as rospy and roscpp
  std::vector<std::uint8_t> request, response;
  do {
    std::uint8_t len_bytes[4];
    // A persistent client may stay quiet for as long as it likes; the wake pipe ends the wait at shutdown.
    if (!socket.readAll(len_bytes, 4, SteadyClock::time_point::max(), wake_[0])) return;
    const std::uint32_t len = readLength(len_bytes);
    if (len > kMaxMessageBytes) {
      ROS_WARN("service %s: dropped a client sending a request of %u bytes", name_.c_str(), len);
      return;
    }
    request.resize(len);
    if (!socket.readAll(request.data(), request.size(), after(kMessageTimeout), wake_[0])) return;
    response.clear();
    bool ok = false;
    try {
      ok = handler_(request.data(), request.size(), &response, &error);
    } catch (const std::exception& e) {
      error = e.what();
    }
    if (!ok) ROS_ERROR("service %s: %s", name_.c_str(), error.c_str());
    std::vector<std::uint8_t> out(5);
    out[0] = ok ? 1 : 0;
    if (!ok) response.assign(error.begin(), error.end());  // an error is a string (what clients read after ok 0)
    const std::uint32_t out_len = static_cast<std::uint32_t>(response.size());
    std::memcpy(out.data() + 1, &out_len, 4);
    out.insert(out.end(), response.begin(), response.end());
    if (!socket.writeAll(out.data(), out.size(), after(kMessageTimeout))) return;
  } while (persistent && !stop_);
}

}  // namespace moverl_tcpros
