// A TCPROS service client whose calls are made in the calling thread, end by a deadline, and send a request at most
// once (README.md).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <ros/console.h>
#include <ros/serialization.h>
#include <ros/service_traits.h>

#include "moverl_tcpros/socket.h"

namespace moverl_tcpros {

/// \brief A TCPROS service client. Every call ends with an answer, or with a CallEnd saying why not, by its deadline.
///
/// At most once: a request is written again only when it provably never reached the server, that is when writing it
/// failed on an idle persistent connection (a TCPROS server acts on whole requests only, and a failed write delivered
/// part of one at most). A persistent connection that the server closed while it was idle is noticed before the
/// request is written (one poll(2)), and the request goes over a new connection. A connection that closes while the
/// answer is awaited ends the call with kClosed: the server may have acted on the request, which is never sent again.
///
/// One call at a time (the calling thread does all the work; callers that share a client serialize their calls).
class ServiceClient {
 public:
  /// \brief A client of `service` (resolved name) whose requests and answers have this md5sum ("*": any). Persistent:
  ///        one connection for all calls while it works (header persistent=1); else a connection per call.
  ServiceClient(std::string service, std::string md5sum, bool persistent = true);
  const std::string& name() const { return name_; }
  /// \brief Send a serialized request ([4-byte length][payload]) and read the answer's payload into *response, before
  ///        the deadline. *error says what went wrong when the result is not kAnswered.
  CallEnd call(const std::uint8_t* request, std::size_t n, SteadyClock::time_point deadline,
               std::vector<std::uint8_t>* response, std::string* error);
  /// \brief Connections opened so far (connection headers exchanged): one for a persistent client whose server stayed
  ///        up.
  std::size_t connections() const { return connections_; }

 private:
  bool open(SteadyClock::time_point deadline, std::string* error);
  bool connectToService(SteadyClock::time_point deadline, std::string* error);
  CallEnd notOpened(SteadyClock::time_point deadline) const;
  CallEnd answerLost(const std::string& what, std::string* error);

  std::string name_, md5_;
  bool persistent_;
  std::string host_;        ///< where the service was last found
  std::uint32_t port_ = 0;  ///< 0: ask the master
  Socket socket_;
  std::size_t connections_ = 0;
};

/// \brief A typed ServiceClient: `call(srv, timeout)` fills srv.response, with a deadline `timeout` s from now.
template <class Srv>
class DirectServiceClient {
 public:
  explicit DirectServiceClient(const std::string& resolved_name, bool persistent = true)
      : client_(resolved_name, ros::service_traits::md5sum<Srv>(), persistent) {}
  const std::string& name() const { return client_.name(); }
  /// \brief What the last call that did not end kAnswered said went wrong.
  const std::string& error() const { return error_; }
  std::size_t connections() const { return client_.connections(); }

  /// \brief Call the service with srv.request; on kAnswered srv.response holds the answer. A warning is logged
  ///        otherwise (the caller's verdict names the service; the warning says what went wrong).
  CallEnd call(Srv& srv, double timeout) {
    const ros::SerializedMessage request = ros::serialization::serializeMessage(srv.request);
    const CallEnd end = client_.call(request.buf.get(), request.num_bytes, after(timeout), &buffer_, &error_);
    if (end != CallEnd::kAnswered) {
      ROS_WARN("%s", error_.c_str());
      return end;
    }
    try {
      ros::serialization::IStream in(buffer_.data(), static_cast<std::uint32_t>(buffer_.size()));
      ros::serialization::deserialize(in, srv.response);
    } catch (const std::exception& e) {
      error_ = "service " + client_.name() + ": cannot read the answer: " + e.what();
      ROS_WARN("%s", error_.c_str());
      return CallEnd::kFailed;
    }
    return CallEnd::kAnswered;
  }

 private:
  ServiceClient client_;
  std::vector<std::uint8_t> buffer_;
  std::string error_;
};

}  // namespace moverl_tcpros
