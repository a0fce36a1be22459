#include "tcpros.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include <ros/header.h>
#include <ros/master.h>
#include <ros/network.h>
#include <ros/service_manager.h>
#include <ros/this_node.h>
#include <ros/xmlrpc_manager.h>

namespace moverl_shield {
namespace {

/// A bound on reading a request or a header once its first byte is there, and on writing an answer: a peer that
/// stops half-way through a message is dropped instead of holding a server thread.
constexpr double kMessageTimeout = 5.0;
/// Larger requests and answers are refused (a corrupt length must not allocate gigabytes); a step's are under 1 kB.
constexpr std::uint32_t kMaxMessageBytes = 64u << 20;

int millisecondsUntil(SteadyClock::time_point deadline) {
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - SteadyClock::now()).count();
  return left <= 0 ? 0 : static_cast<int>(std::min<long long>(left + 1, 1 << 30));
}

void setNoDelay(int fd) {
  int one = 1;
  setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
}

std::uint32_t readLength(const std::uint8_t* b) {
  std::uint32_t v;
  std::memcpy(&v, b, 4);  // little endian on the wire, as on every host ROS 1 runs on
  return v;
}

}  // namespace

// ---------------------------------------------------------------------------------------------------- TcprosSocket
TcprosSocket::TcprosSocket(int fd) : fd_(fd) {
  fcntl(fd_, F_SETFL, fcntl(fd_, F_GETFL) | O_NONBLOCK);
  setNoDelay(fd_);
}

void TcprosSocket::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

bool TcprosSocket::wait(short events, SteadyClock::time_point deadline, int wake) {
  pollfd fds[2] = {{fd_, events, 0}, {wake, POLLIN, 0}};
  for (;;) {
    const int n = ::poll(fds, wake >= 0 ? 2 : 1, millisecondsUntil(deadline));
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) return false;
    if (wake >= 0 && fds[1].revents) return false;
    if (fds[0].revents) return true;  // ready, or an error the next read / write reports
    if (SteadyClock::now() >= deadline) {
      timed_out_ = true;
      return false;
    }
  }
}

bool TcprosSocket::connect(const std::string& host, std::uint32_t port, SteadyClock::time_point deadline,
                           std::string* error) {
  close();
  timed_out_ = false;
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  if (getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &res) != 0 || res == nullptr) {
    *error = "cannot resolve host " + host;
    return false;
  }
  fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  const int rc = fd_ < 0 ? -1 : ::connect(fd_, res->ai_addr, res->ai_addrlen);
  freeaddrinfo(res);
  if (fd_ < 0 || (rc < 0 && errno != EINPROGRESS)) {
    *error = "cannot connect to " + host + ":" + std::to_string(port) + ": " + std::strerror(errno);
    close();
    return false;
  }
  if (rc < 0) {
    int so_error = 0;
    socklen_t len = sizeof(so_error);
    if (!wait(POLLOUT, deadline, -1) || getsockopt(fd_, SOL_SOCKET, SO_ERROR, &so_error, &len) < 0 || so_error) {
      *error = "cannot connect to " + host + ":" + std::to_string(port) + ": " +
               (timed_out_ ? std::string("timed out") : std::string(std::strerror(so_error)));
      close();
      return false;
    }
  }
  setNoDelay(fd_);
  return true;
}

bool TcprosSocket::writeAll(const std::uint8_t* data, std::size_t n, SteadyClock::time_point deadline) {
  while (n > 0) {
    const ssize_t k = ::send(fd_, data, n, MSG_NOSIGNAL);
    if (k > 0) {
      data += k;
      n -= static_cast<std::size_t>(k);
      continue;
    }
    if (k < 0 && errno == EINTR) continue;
    if (k < 0 && (errno == EAGAIN || errno == EWOULDBLOCK) && wait(POLLOUT, deadline, -1)) continue;
    return false;
  }
  return true;
}

bool TcprosSocket::readAll(std::uint8_t* data, std::size_t n, SteadyClock::time_point deadline, int wake) {
  while (n > 0) {
    const ssize_t k = ::recv(fd_, data, n, 0);
    if (k > 0) {
      data += k;
      n -= static_cast<std::size_t>(k);
      continue;
    }
    if (k == 0) return false;  // closed by the peer
    if (errno == EINTR) continue;
    if ((errno == EAGAIN || errno == EWOULDBLOCK) && wait(POLLIN, deadline, wake)) continue;
    return false;
  }
  return true;
}

bool TcprosSocket::writeHeader(const std::map<std::string, std::string>& fields, SteadyClock::time_point deadline) {
  boost::shared_array<std::uint8_t> buffer;
  std::uint32_t size = 0;
  ros::Header::write(fields, buffer, size);
  std::vector<std::uint8_t> out(4 + size);
  std::memcpy(out.data(), &size, 4);
  if (size > 0) std::memcpy(out.data() + 4, buffer.get(), size);
  return writeAll(out.data(), out.size(), deadline);
}

bool TcprosSocket::readHeader(std::map<std::string, std::string>* fields, SteadyClock::time_point deadline,
                              std::string* error, int wake) {
  std::uint8_t len_bytes[4];
  if (!readAll(len_bytes, 4, deadline, wake)) {
    *error = timed_out_ ? "no connection header in time" : "the connection closed before its header";
    return false;
  }
  const std::uint32_t len = readLength(len_bytes);
  if (len > (1u << 20)) {
    *error = "connection header of " + std::to_string(len) + " bytes";
    return false;
  }
  boost::shared_array<std::uint8_t> buffer(new std::uint8_t[len > 0 ? len : 1]);
  if (!readAll(buffer.get(), len, deadline, wake)) {
    *error = "the connection header was cut short";
    return false;
  }
  ros::Header header;
  std::string parse_error;
  if (!header.parse(buffer, len, parse_error)) {
    *error = "bad connection header: " + parse_error;
    return false;
  }
  *fields = *header.getValues();
  return true;
}

// ----------------------------------------------------------------------------------------------- TcprosServiceClient
bool TcprosServiceClient::open(SteadyClock::time_point deadline, std::string* error) {
  // The master is asked where the service is only when the last address fails (an XML-RPC call has no deadline of its
  // own; a restarted server has a new port).
  if (port_ == 0 || !socket_.connect(host_, port_, deadline, error)) {
    if (!ros::ServiceManager::instance()->lookupService(name_, host_, port_)) {
      port_ = 0;
      *error = "service " + name_ + " is not advertised";
      return false;
    }
    if (SteadyClock::now() >= deadline) {
      *error = "no time left to connect to " + name_;
      return false;
    }
    if (!socket_.connect(host_, port_, deadline, error)) return false;
  }
  const std::map<std::string, std::string> fields = {
      {"callerid", ros::this_node::getName()}, {"service", name_}, {"md5sum", md5_}, {"persistent", "1"}};
  std::map<std::string, std::string> answer;
  if (!socket_.writeHeader(fields, deadline) || !socket_.readHeader(&answer, deadline, error)) {
    if (error->empty() || socket_.timedOut()) *error = "no answer to the connection header";
    socket_.close();
    port_ = 0;  // perhaps no longer the service's address: ask the master next time
    return false;
  }
  const auto bad = answer.find("error");
  if (bad != answer.end()) {
    *error = "service " + name_ + " refused the connection: " + bad->second;
    socket_.close();
    port_ = 0;
    return false;
  }
  return true;
}

CallEnd TcprosServiceClient::call(const std::uint8_t* request, std::size_t n, SteadyClock::time_point deadline,
                                  std::vector<std::uint8_t>* response, std::string* error) {
  error->clear();
  for (int attempt = 0; attempt < 2; ++attempt) {
    if (!socket_.isOpen() && !open(deadline, error)) {
      if (SteadyClock::now() >= deadline) return CallEnd::kTimedOut;
      return CallEnd::kUnreachable;  // not advertised, refused: nothing to wait for
    }
    std::uint8_t head[5];
    bool ok = socket_.writeAll(request, n, deadline) && socket_.readAll(head, 5, deadline);
    if (ok) {
      const std::uint32_t len = readLength(head + 1);
      if (len > kMaxMessageBytes) {  // not an answer of this service: the stream is out of step
        *error = "service " + name_ + " sent an answer of " + std::to_string(len) + " bytes";
        socket_.close();
        return CallEnd::kUnreachable;
      }
      response->resize(len);
      ok = socket_.readAll(response->data(), len, deadline);
      if (ok && head[0] != 1) {
        // The server could not handle the request (its message follows, as a length-prefixed string).
        *error = "service " + name_ + " failed: " + std::string(response->begin(), response->end());
        socket_.close();
        return CallEnd::kUnreachable;
      }
      if (ok) return CallEnd::kAnswered;
    }
    const bool timed_out = socket_.timedOut() || SteadyClock::now() >= deadline;
    socket_.close();  // a late answer must never be read as the next call's
    if (timed_out) {
      *error = "service " + name_ + " did not answer in time";
      return CallEnd::kTimedOut;
    }
    *error = "service " + name_ + " closed the connection";
  }
  return CallEnd::kUnreachable;
}

// ----------------------------------------------------------------------------------------------- TcprosServiceServer
TcprosServiceServer::TcprosServiceServer(std::string resolved_name, Type type, RawHandler handler)
    : name_(std::move(resolved_name)), type_(std::move(type)), handler_(std::move(handler)) {
  const std::string& host = ros::network::getHost();
  // Listen where the node says it can be reached: only on the loopback interface when that is its address.
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = 0;
  addr.sin_addr.s_addr = htonl(INADDR_ANY);
  in_addr host_addr{};
  if (host == "localhost" ||
      (inet_pton(AF_INET, host.c_str(), &host_addr) == 1 && (ntohl(host_addr.s_addr) >> 24) == 127)) {
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  }
  listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  socklen_t len = sizeof(addr);
  if (listen_fd_ < 0 || ::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) < 0 ||
      ::listen(listen_fd_, 16) < 0 || getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len) < 0 ||
      ::pipe2(wake_, O_CLOEXEC) < 0) {
    const std::string why = std::strerror(errno);
    if (listen_fd_ >= 0) ::close(listen_fd_);
    throw std::runtime_error("cannot listen for service " + name_ + ": " + why);
  }
  uri_ = "rosrpc://" + host + ":" + std::to_string(ntohs(addr.sin_port));
  accept_thread_ = std::thread([this] { acceptLoop(); });
  if (!registerWithMaster("registerService")) {
    stopAndJoin();
    throw std::runtime_error("cannot register service " + name_ + " with the master");
  }
}

TcprosServiceServer::~TcprosServiceServer() {
  registerWithMaster("unregisterService");
  stopAndJoin();
}

void TcprosServiceServer::stopAndJoin() {
  stop_ = true;
  const char b = 0;
  (void)!::write(wake_[1], &b, 1);  // every thread polls the pipe's read end: all wake up and return
  accept_thread_.join();
  std::lock_guard<std::mutex> lock(threads_mutex_);
  for (auto& c : threads_) c.thread.join();  // a running handler finishes first (its own deadlines bound it)
  ::close(listen_fd_);
  ::close(wake_[0]);
  ::close(wake_[1]);
}

bool TcprosServiceServer::registerWithMaster(const char* method) {
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  args[1] = name_;
  args[2] = uri_;
  if (std::string(method) == "registerService") args[3] = ros::XMLRPCManager::instance()->getServerURI();
  return ros::master::execute(method, args, result, payload, false);
}

void TcprosServiceServer::acceptLoop() {
  pollfd fds[2] = {{listen_fd_, POLLIN, 0}, {wake_[0], POLLIN, 0}};
  while (!stop_) {
    if (::poll(fds, 2, -1) < 0) {
      if (errno == EINTR) continue;
      ROS_ERROR("service %s: poll failed: %s", name_.c_str(), std::strerror(errno));
      return;
    }
    if (fds[1].revents || stop_) return;
    if (!fds[0].revents) continue;
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (fd < 0) {
      if (errno == EMFILE || errno == ENFILE || errno == ENOMEM || errno == ENOBUFS) {
        ROS_ERROR_THROTTLE(10.0, "service %s: cannot accept a client: %s", name_.c_str(), std::strerror(errno));
        std::this_thread::sleep_for(std::chrono::milliseconds(100));  // the client stays queued: no busy loop
      }
      continue;  // EAGAIN: the client left before it was accepted
    }
    std::lock_guard<std::mutex> lock(threads_mutex_);
    for (auto it = threads_.begin(); it != threads_.end();) {  // join the connections that ended
      if (it->done->load()) {
        it->thread.join();
        it = threads_.erase(it);
      } else {
        ++it;
      }
    }
    try {
      auto done = std::make_shared<std::atomic<bool>>(false);
      threads_.push_back(Connection{std::thread([this, fd, done] {
                                      try {
                                        serve(fd);
                                      } catch (const std::exception& e) {  // the connection ends, never the node
                                        ROS_ERROR("service %s: %s", name_.c_str(), e.what());
                                      }
                                      *done = true;
                                    }),
                                    done});
    } catch (const std::exception& e) {  // no thread for it: the client is dropped
      ROS_ERROR("service %s: cannot serve a client: %s", name_.c_str(), e.what());
      ::close(fd);
    }
  }
}

void TcprosServiceServer::serve(int fd) {
  TcprosSocket socket(fd);
  std::map<std::string, std::string> header;
  std::string error;
  if (!socket.readHeader(&header, after(kMessageTimeout), &error, wake_[0])) return;
  const std::string md5 = header.count("md5sum") ? header["md5sum"] : "";
  std::map<std::string, std::string> answer = {{"callerid", ros::this_node::getName()},
                                               {"md5sum", type_.md5sum},
                                               {"type", type_.datatype},
                                               {"request_type", type_.request_type},
                                               {"response_type", type_.response_type}};
  if (header["service"] != name_) {
    answer = {{"error", "this connection serves " + name_ + ", not " + header["service"]}};
  } else if (md5 != "*" && md5 != type_.md5sum) {
    answer = {{"error", "md5sums do not match: [" + md5 + "] vs. [" + type_.md5sum + "]"}};
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
    if (!ok) {
      // An error is a length-prefixed string (what rospy and roscpp clients read after a 0 ok byte).
      response.assign(error.begin(), error.end());
    }
    const std::uint32_t out_len = static_cast<std::uint32_t>(response.size());
    std::memcpy(out.data() + 1, &out_len, 4);
    out.insert(out.end(), response.begin(), response.end());
    if (!socket.writeAll(out.data(), out.size(), after(kMessageTimeout))) return;
  } while (persistent && !stop_);
}

}  // namespace moverl_shield
