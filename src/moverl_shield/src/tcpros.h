// ROS services on the step's hot path, spoken directly over TCPROS by the thread that needs them. ROS part of the
// shield node.
//
// Why: roscpp hands every service request and response between threads. A request arrives on its poll thread, waits in
// a callback queue for the spinner thread, and a client call blocks on a condition variable until the poll thread has
// read the answer; enabling and disabling each write wakes the poll thread once more. Counted per lockstep env step
// (/proc/<pid>/task/*/status, 2,000 steps): 11.7 context switches in the shield, against about 1 in the env and in
// the simulator (rospy reads and writes in the calling thread). On this 2-core VM the kernel then took 42 % of the
// shield's CPU (perf). Here the thread that serves ~step reads the request, calls the simulator and writes the answer
// itself: two wake-ups per step.
//
// The wire format is TCPROS (wiki.ros.org/ROS/TCPROS): the services are registered with the master and reached by
// any ROS client (rospy, roscpp, `rosservice call`) as before. Every connect, read and write has a deadline
// (poll(2)), so a stalled peer costs at most the caller's timeout, and a timed-out connection is closed: a late answer
// is never read as the answer to a later request. Not bounded: asking the master where a service is (an XML-RPC call,
// as roscpp's own clients make it), done only when the last address fails.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <ros/console.h>
#include <ros/serialization.h>
#include <ros/service_traits.h>

#include "deadline.h"

namespace moverl_shield {

/// \brief A TCP socket whose reads and writes end at a deadline.
class TcprosSocket {
 public:
  TcprosSocket() = default;
  explicit TcprosSocket(int fd);
  ~TcprosSocket() { close(); }
  TcprosSocket(const TcprosSocket&) = delete;
  TcprosSocket& operator=(const TcprosSocket&) = delete;

  /// \brief Connect to host:port before the deadline. False with *error if not.
  bool connect(const std::string& host, std::uint32_t port, SteadyClock::time_point deadline, std::string* error);
  bool isOpen() const { return fd_ >= 0; }
  void close();
  /// \brief Write all n bytes before the deadline. False on a closed connection or at the deadline (timedOut()).
  bool writeAll(const std::uint8_t* data, std::size_t n, SteadyClock::time_point deadline);
  /// \brief Read exactly n bytes before the deadline; also returns false when `wake` (a pipe's read end, or -1)
  ///        becomes readable (the owner shuts down).
  bool readAll(std::uint8_t* data, std::size_t n, SteadyClock::time_point deadline, int wake = -1);
  bool timedOut() const { return timed_out_; }

  /// \brief Write a connection header (TCPROS: a 4-byte length, then length-prefixed "key=value" fields).
  bool writeHeader(const std::map<std::string, std::string>& fields, SteadyClock::time_point deadline);
  /// \brief Read a connection header into *fields. False with *error on a bad or missing header.
  bool readHeader(std::map<std::string, std::string>* fields, SteadyClock::time_point deadline, std::string* error,
                  int wake = -1);

 private:
  bool wait(short events, SteadyClock::time_point deadline, int wake);
  int fd_ = -1;
  bool timed_out_ = false;
};

/// \brief A persistent TCPROS service client whose calls have a deadline, made in the calling thread. Every call ends
///        with an answer, or with a CallEnd (deadline.h) saying why not, by its deadline; a broken connection (a
///        restarted server) is re-opened once, never waited for.
class TcprosServiceClient {
 public:
  TcprosServiceClient(std::string service, std::string md5sum) : name_(std::move(service)), md5_(std::move(md5sum)) {}
  const std::string& name() const { return name_; }
  /// \brief Send a serialized request ([4-byte length][payload]) and read the answer's payload into *response.
  ///        Before the deadline; *error says what went wrong when it is not kAnswered.
  CallEnd call(const std::uint8_t* request, std::size_t n, SteadyClock::time_point deadline,
               std::vector<std::uint8_t>* response, std::string* error);

 private:
  bool open(SteadyClock::time_point deadline, std::string* error);
  std::string name_, md5_;
  std::string host_;        ///< where the service was last found
  std::uint32_t port_ = 0;  ///< 0: ask the master
  TcprosSocket socket_;
};

/// \brief A typed TcprosServiceClient: `call(srv, timeout)` fills srv.response, with a deadline `timeout` s from now.
template <class Srv>
class DirectServiceClient {
 public:
  explicit DirectServiceClient(const std::string& resolved_name)
      : client_(resolved_name, ros::service_traits::md5sum<Srv>()) {}
  const std::string& name() const { return client_.name(); }

  CallEnd call(Srv& srv, double timeout) {
    const ros::SerializedMessage request = ros::serialization::serializeMessage(srv.request);
    const CallEnd end = client_.call(request.buf.get(), request.num_bytes, after(timeout), &buffer_, &error_);
    if (end != CallEnd::kAnswered) {
      ROS_WARN("%s", error_.c_str());  // the caller's verdict names the service; this says what went wrong
      return end;
    }
    try {
      ros::serialization::IStream in(buffer_.data(), static_cast<std::uint32_t>(buffer_.size()));
      ros::serialization::deserialize(in, srv.response);
    } catch (const std::exception& e) {
      error_ = std::string("cannot read the answer: ") + e.what();
      return CallEnd::kUnreachable;
    }
    return CallEnd::kAnswered;
  }

 private:
  TcprosServiceClient client_;
  std::vector<std::uint8_t> buffer_;
  std::string error_;
};

/// \brief A ROS service served over TCPROS by threads of its own: one per connected client, each reading a request,
///        running the handler and writing the answer. Registered with the master on construction, unregistered on
///        destruction (which waits for a handler that is running).
class TcprosServiceServer {
 public:
  /// Handler: request payload -> response payload (serialized), or false with an error message for the client.
  using RawHandler = std::function<bool(const std::uint8_t* request, std::size_t n, std::vector<std::uint8_t>* response,
                                        std::string* error)>;
  struct Type {
    std::string md5sum, datatype, request_type, response_type;
  };
  TcprosServiceServer(std::string resolved_name, Type type, RawHandler handler);
  ~TcprosServiceServer();
  TcprosServiceServer(const TcprosServiceServer&) = delete;
  TcprosServiceServer& operator=(const TcprosServiceServer&) = delete;

 private:
  void acceptLoop();
  void stopAndJoin();
  void serve(int fd);
  bool registerWithMaster(const char* method);
  std::string name_, uri_;
  Type type_;
  RawHandler handler_;
  int listen_fd_ = -1, wake_[2] = {-1, -1};
  std::atomic<bool> stop_{false};
  struct Connection {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> done;
  };
  std::mutex threads_mutex_;
  std::list<Connection> threads_;
  std::thread accept_thread_;
};

/// \brief Serve the service Srv at `resolved_name` with `handler(request, response)` (a roscpp-style callback).
template <class Srv>
std::unique_ptr<TcprosServiceServer> advertiseDirect(
    const std::string& resolved_name, std::function<bool(typename Srv::Request&, typename Srv::Response&)> handler) {
  using Req = typename Srv::Request;
  using Res = typename Srv::Response;
  TcprosServiceServer::Type type{ros::service_traits::md5sum<Srv>(), ros::service_traits::datatype<Srv>(),
                                 ros::message_traits::datatype<Req>(), ros::message_traits::datatype<Res>()};
  auto raw = [handler](const std::uint8_t* data, std::size_t n, std::vector<std::uint8_t>* out, std::string* error) {
    Req req;
    Res res;
    try {
      ros::serialization::IStream in(const_cast<std::uint8_t*>(data), static_cast<std::uint32_t>(n));
      ros::serialization::deserialize(in, req);
    } catch (const std::exception& e) {
      *error = std::string("cannot read the request: ") + e.what();
      return false;
    }
    if (!handler(req, res)) {
      *error = "the service handler failed";
      return false;
    }
    const std::uint32_t len = ros::serialization::serializationLength(res);
    out->resize(len);
    ros::serialization::OStream o(out->data(), len);
    ros::serialization::serialize(o, res);
    return true;
  };
  return std::make_unique<TcprosServiceServer>(resolved_name, std::move(type), std::move(raw));
}

}  // namespace moverl_shield
