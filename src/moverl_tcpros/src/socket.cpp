#include "moverl_tcpros/socket.h"

#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>

namespace moverl_tcpros {
namespace {

int millisecondsUntil(SteadyClock::time_point deadline) {
  if (deadline == SteadyClock::time_point::max()) return -1;
  const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - SteadyClock::now()).count();
  return left <= 0 ? 0 : static_cast<int>(std::min<long long>(left + 1, 1 << 30));
}

void setNoDelay(int fd) {
  int one = 1;
  setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
}

void appendLength(std::vector<std::uint8_t>* out, std::uint32_t n) {
  std::uint8_t b[4];
  std::memcpy(b, &n, 4);  // little endian on the wire, as on every host ROS 1 runs on
  out->insert(out->end(), b, b + 4);
}

bool peerGone(int error) { return error == ECONNRESET || error == EPIPE || error == ENOTCONN; }

}  // namespace

std::uint32_t readLength(const std::uint8_t* bytes) {
  std::uint32_t v;
  std::memcpy(&v, bytes, 4);
  return v;
}

// ------------------------------------------------------------------------------------------------------ wire format
std::vector<std::uint8_t> encodeHeader(const HeaderFields& fields) {
  std::vector<std::uint8_t> out;
  for (const auto& kv : fields) {
    const std::string field = kv.first + "=" + kv.second;
    appendLength(&out, static_cast<std::uint32_t>(field.size()));
    out.insert(out.end(), field.begin(), field.end());
  }
  return out;
}

bool decodeHeader(const std::uint8_t* data, std::size_t n, HeaderFields* fields, std::string* error) {
  fields->clear();
  std::size_t pos = 0;
  while (pos < n) {
    if (n - pos < 4) {
      *error = "a field's length is cut short";
      return false;
    }
    const std::uint32_t len = readLength(data + pos);
    pos += 4;
    if (len > n - pos) {
      *error = "a field of " + std::to_string(len) + " bytes runs past the header's end";
      return false;
    }
    const std::string field(reinterpret_cast<const char*>(data + pos), len);
    pos += len;
    const std::size_t eq = field.find('=');
    if (eq == std::string::npos) {
      *error = "a field without '=' (" + field.substr(0, 40) + ")";
      return false;
    }
    (*fields)[field.substr(0, eq)] = field.substr(eq + 1);
  }
  return true;
}

bool splitRosrpcUri(const std::string& uri, std::string* host, std::uint32_t* port) {
  const std::string scheme = "rosrpc://";
  if (uri.compare(0, scheme.size(), scheme) != 0) return false;
  std::string rest = uri.substr(scheme.size());
  std::string port_text;
  if (!rest.empty() && rest[0] == '[') {  // [IPv6 literal]:port
    const std::size_t close = rest.find(']');
    if (close == std::string::npos || close + 1 >= rest.size() || rest[close + 1] != ':') return false;
    *host = rest.substr(1, close - 1);
    port_text = rest.substr(close + 2);
  } else {
    const std::size_t colon = rest.rfind(':');
    if (colon == std::string::npos) return false;
    *host = rest.substr(0, colon);
    port_text = rest.substr(colon + 1);
  }
  const std::size_t slash = port_text.find('/');
  if (slash != std::string::npos) port_text.erase(slash);
  if (host->empty() || port_text.empty() || port_text.size() > 5 ||
      !std::all_of(port_text.begin(), port_text.end(), [](char c) { return c >= '0' && c <= '9'; })) {
    return false;
  }
  const unsigned long p = std::stoul(port_text);
  if (p == 0 || p > 65535) return false;
  *port = static_cast<std::uint32_t>(p);
  return true;
}

std::string rosrpcUri(const std::string& host, std::uint32_t port) {
  const bool v6_literal = host.find(':') != std::string::npos;
  return "rosrpc://" + (v6_literal ? "[" + host + "]" : host) + ":" + std::to_string(port);
}

// ----------------------------------------------------------------------------------------------------------- Socket
Socket::Socket(int fd) : fd_(fd) {
  fcntl(fd_, F_SETFL, fcntl(fd_, F_GETFL) | O_NONBLOCK);
  setNoDelay(fd_);
}

void Socket::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

bool Socket::wait(short events, SteadyClock::time_point deadline, int wake) {
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

bool Socket::connect(const std::string& host, std::uint32_t port, SteadyClock::time_point deadline,
                     std::string* error) {
  close();
  timed_out_ = closed_by_peer_ = false;
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;  // IPv6 and IPv4, in the order the system prefers
  hints.ai_socktype = SOCK_STREAM;
  addrinfo* res = nullptr;
  const int rc = getaddrinfo(host.c_str(), std::to_string(port).c_str(), &hints, &res);
  if (rc != 0 || res == nullptr) {
    *error = "cannot resolve host " + host + ": " + gai_strerror(rc);
    return false;
  }
  const std::string where = host + ":" + std::to_string(port);
  std::string why = "no address";
  for (const addrinfo* ai = res; ai != nullptr; ai = ai->ai_next) {
    fd_ = ::socket(ai->ai_family, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd_ < 0) {
      why = std::strerror(errno);
      continue;
    }
    if (::connect(fd_, ai->ai_addr, ai->ai_addrlen) < 0) {
      int so_error = errno;
      if (so_error == EINPROGRESS) {
        socklen_t len = sizeof(so_error);
        so_error = 0;
        if (!wait(POLLOUT, deadline, -1)) {
          why = "timed out";
          close();
          break;  // the deadline is the call's: no time for the next address
        }
        if (getsockopt(fd_, SOL_SOCKET, SO_ERROR, &so_error, &len) < 0) so_error = errno;
      }
      if (so_error != 0) {
        why = std::strerror(so_error);
        close();
        continue;
      }
    }
    setNoDelay(fd_);
    freeaddrinfo(res);
    return true;
  }
  freeaddrinfo(res);
  *error = "cannot connect to " + where + ": " + why;
  return false;
}

bool Socket::idle() const {
  if (fd_ < 0) return false;
  pollfd p{fd_, static_cast<short>(POLLIN | POLLRDHUP), 0};
  int n;
  do {
    n = ::poll(&p, 1, 0);
  } while (n < 0 && errno == EINTR);
  return n == 0;  // any event: the peer closed or reset it, or sent bytes nobody asked for
}

bool Socket::writeAll(const std::uint8_t* data, std::size_t n, SteadyClock::time_point deadline) {
  timed_out_ = closed_by_peer_ = false;
  while (n > 0) {
    const ssize_t k = ::send(fd_, data, n, MSG_NOSIGNAL);
    if (k > 0) {
      data += k;
      n -= static_cast<std::size_t>(k);
      continue;
    }
    if (k < 0 && errno == EINTR) continue;
    if (k < 0 && (errno == EAGAIN || errno == EWOULDBLOCK) && wait(POLLOUT, deadline, -1)) continue;
    if (k < 0 && peerGone(errno)) closed_by_peer_ = true;
    return false;
  }
  return true;
}

bool Socket::readAll(std::uint8_t* data, std::size_t n, SteadyClock::time_point deadline, int wake) {
  timed_out_ = closed_by_peer_ = false;
  while (n > 0) {
    const ssize_t k = ::recv(fd_, data, n, 0);
    if (k > 0) {
      data += k;
      n -= static_cast<std::size_t>(k);
      continue;
    }
    if (k == 0) {
      closed_by_peer_ = true;
      return false;
    }
    if (errno == EINTR) continue;
    if ((errno == EAGAIN || errno == EWOULDBLOCK) && wait(POLLIN, deadline, wake)) continue;
    if (peerGone(errno)) closed_by_peer_ = true;
    return false;
  }
  return true;
}

bool Socket::writeHeader(const HeaderFields& fields, SteadyClock::time_point deadline) {
  const std::vector<std::uint8_t> body = encodeHeader(fields);
  std::vector<std::uint8_t> out;
  out.reserve(4 + body.size());
  appendLength(&out, static_cast<std::uint32_t>(body.size()));
  out.insert(out.end(), body.begin(), body.end());
  return writeAll(out.data(), out.size(), deadline);
}

bool Socket::readHeader(HeaderFields* fields, SteadyClock::time_point deadline, std::string* error, int wake) {
  std::uint8_t len_bytes[4];
  if (!readAll(len_bytes, 4, deadline, wake)) {
    *error = timed_out_ ? "no connection header in time" : "the connection closed before its header";
    return false;
  }
  const std::uint32_t len = readLength(len_bytes);
  if (len > kMaxHeaderBytes) {
    *error = "a connection header of " + std::to_string(len) + " bytes";
    return false;
  }
  std::vector<std::uint8_t> body(len);
  if (!readAll(body.data(), len, deadline, wake)) {
    *error = timed_out_ ? "the connection header did not arrive in time" : "the connection header was cut short";
    return false;
  }
  std::string why;
  if (!decodeHeader(body.data(), body.size(), fields, &why)) {
    *error = "bad connection header: " + why;
    return false;
  }
  return true;
}

}  // namespace moverl_tcpros
