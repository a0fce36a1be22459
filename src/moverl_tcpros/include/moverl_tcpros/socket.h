// TCPROS on a socket whose every connect, read and write ends at a deadline (poll(2) timeouts). No ROS headers here:
// the wire format is written out in full (wiki.ros.org/ROS/TCPROS).
//
//   connection header  [4-byte length] then fields, each [4-byte length]"key=value"   (both ways, once per connection)
//   request            [4-byte length][serialized request]                             (client -> server)
//   answer             [1-byte ok][4-byte length][serialized response, or an error string when ok is 0]
//
// Lengths are little endian, as on every host ROS 1 runs on.
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "moverl_tcpros/call_end.h"

namespace moverl_tcpros {

using HeaderFields = std::map<std::string, std::string>;

/// Larger requests and answers are refused (a corrupt length must not allocate gigabytes).
constexpr std::uint32_t kMaxMessageBytes = 64u << 20;
/// Larger connection headers are refused.
constexpr std::uint32_t kMaxHeaderBytes = 1u << 20;

/// \brief The body of a connection header (without its own 4-byte length).
std::vector<std::uint8_t> encodeHeader(const HeaderFields& fields);
/// \brief Parse a connection header's body into *fields. False with *error when a field's length runs past the end or
///        a field has no '='.
bool decodeHeader(const std::uint8_t* data, std::size_t n, HeaderFields* fields, std::string* error);

/// \brief Split "rosrpc://host:port" (also "rosrpc://[v6 literal]:port", and a trailing '/') into host and port.
///        False when it is not such a URI.
bool splitRosrpcUri(const std::string& uri, std::string* host, std::uint32_t* port);
/// \brief "rosrpc://host:port", with an IPv6 literal in brackets (which rospy and roscpp clients cannot parse: ROS 1
///        clients reach IPv6 services by host name only).
std::string rosrpcUri(const std::string& host, std::uint32_t port);

/// \brief A TCP socket (IPv4 or IPv6) whose reads and writes end at a deadline.
class Socket {
 public:
  Socket() = default;
  /// \brief Take an accepted socket (made non-blocking, TCP_NODELAY).
  explicit Socket(int fd);
  ~Socket() { close(); }
  Socket(const Socket&) = delete;
  Socket& operator=(const Socket&) = delete;

  /// \brief Connect to host:port before the deadline, trying each address getaddrinfo gives for host in turn (IPv6
  ///        and IPv4). False with *error if none connects. Resolving a host name is not bounded (the system's
  ///        resolver; immediate for address literals and /etc/hosts names).
  bool connect(const std::string& host, std::uint32_t port, SteadyClock::time_point deadline, std::string* error);
  bool isOpen() const { return fd_ >= 0; }
  int fd() const { return fd_; }
  void close();
  /// \brief True when the connection is open and idle: the peer has not closed it and sent nothing unasked. Does not
  ///        wait (one poll(2) with a zero timeout).
  bool idle() const;
  /// \brief Write all n bytes before the deadline. False on a closed connection or at the deadline (timedOut()).
  bool writeAll(const std::uint8_t* data, std::size_t n, SteadyClock::time_point deadline);
  /// \brief Read exactly n bytes before the deadline; also returns false when `wake` (a pipe's read end, or -1)
  ///        becomes readable (the owner shuts down). closedByPeer() tells a peer's close from the other ends.
  bool readAll(std::uint8_t* data, std::size_t n, SteadyClock::time_point deadline, int wake = -1);
  /// \brief The last connect, read or write ended at its deadline.
  bool timedOut() const { return timed_out_; }
  /// \brief The last read ended because the peer closed or reset the connection.
  bool closedByPeer() const { return closed_by_peer_; }

  /// \brief Write a connection header.
  bool writeHeader(const HeaderFields& fields, SteadyClock::time_point deadline);
  /// \brief Read a connection header into *fields. False with *error on a bad or missing header.
  bool readHeader(HeaderFields* fields, SteadyClock::time_point deadline, std::string* error, int wake = -1);

 private:
  bool wait(short events, SteadyClock::time_point deadline, int wake);
  int fd_ = -1;
  bool timed_out_ = false;
  bool closed_by_peer_ = false;
};

/// \brief Read a little-endian 4-byte length.
std::uint32_t readLength(const std::uint8_t* bytes);

}  // namespace moverl_tcpros
