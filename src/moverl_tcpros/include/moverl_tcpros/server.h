// A ROS service served over TCPROS by threads of its own: the thread that reads a request runs the handler and writes
// the answer (README.md).
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <ros/serialization.h>
#include <ros/service_traits.h>

#include "moverl_tcpros/socket.h"

namespace moverl_tcpros {

/// \brief How a ServiceServer listens and how many clients it serves.
struct ServerOptions {
  /// Clients served at once (one thread each, for as long as a client stays connected). One more is refused with an
  /// error header and dropped.
  std::size_t max_clients = 8;
  /// The host name or address advertised to the master, and where to listen: on the loopback interface of each
  /// address family the name resolves only to loopback addresses in, else on every address of that family. "": the
  /// node's own (ROS_IP, ROS_HOSTNAME or the host name, as roscpp's).
  std::string host;
  /// s each call to the master (registration, unregistration) may take.
  double master_timeout = 5.0;
};

/// \brief A ROS service served over TCPROS by threads of its own: one per connected client (at most
///        ServerOptions::max_clients), each reading a request, running the handler and writing the answer. Registered
///        with the master on construction (after ros::start(), i.e. the node's first NodeHandle), unregistered on
///        destruction, which then waits for a handler that is running. The master calls do not use roscpp's XML-RPC
///        machinery, so the server may outlive ros::shutdown() and still unregister (a node should destroy its servers
///        before it shuts down, so that nobody finds them while it goes).
class ServiceServer {
 public:
  /// Handler: request payload -> response payload (serialized), or false with an error message for the client.
  using RawHandler = std::function<bool(const std::uint8_t* request, std::size_t n, std::vector<std::uint8_t>* response,
                                        std::string* error)>;
  /// The service's type, as the connection header states it.
  struct Type {
    std::string md5sum, datatype, request_type, response_type;
  };
  /// \brief Listen, start the accept thread and register `resolved_name` with the master. \throws std::runtime_error
  ///        when it cannot listen or register (the master did not answer within options.master_timeout).
  ServiceServer(std::string resolved_name, Type type, RawHandler handler, ServerOptions options = ServerOptions());
  /// \brief Unregister from the master, close every connection, wait for a running handler.
  ~ServiceServer();
  ServiceServer(const ServiceServer&) = delete;
  ServiceServer& operator=(const ServiceServer&) = delete;

  const std::string& name() const { return name_; }
  /// \brief The rosrpc:// URI registered with the master.
  const std::string& uri() const { return uri_; }
  /// \brief Clients connected (being served) now.
  std::size_t clients() const { return active_.load(); }

 private:
  void listen(const std::string& host);
  void acceptLoop();
  void accept(int listen_fd);
  void reapConnections();
  void stopAndJoin();
  void serve(int fd);
  bool unregister(std::string* error);

  std::string name_, uri_;
  Type type_;
  RawHandler handler_;
  ServerOptions options_;
  std::vector<int> listen_fds_;
  int wake_[2] = {-1, -1};
  std::atomic<bool> stop_{false};
  std::atomic<std::size_t> active_{0};
  struct Connection {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> done;
  };
  std::mutex threads_mutex_;
  std::list<Connection> threads_;
  /// Refused clients: their header is read and dropped after the error header went out, so that closing does not
  /// reset the connection before they read it (accept thread only).
  struct Refused {
    int fd;
    SteadyClock::time_point until;
  };
  std::vector<Refused> refused_;
  std::thread accept_thread_;
};

/// \brief Serve the service Srv at `resolved_name` with `handler(request, response)` (a roscpp-style callback).
template <class Srv>
std::unique_ptr<ServiceServer> advertiseDirect(
    const std::string& resolved_name, std::function<bool(typename Srv::Request&, typename Srv::Response&)> handler,
    ServerOptions options = ServerOptions()) {
  using Req = typename Srv::Request;
  using Res = typename Srv::Response;
  ServiceServer::Type type{ros::service_traits::md5sum<Srv>(), ros::service_traits::datatype<Srv>(),
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
  return std::make_unique<ServiceServer>(resolved_name, std::move(type), std::move(raw), std::move(options));
}

}  // namespace moverl_tcpros
