#include "moverl_tcpros/client.h"

#include <ros/this_node.h>

#include "moverl_tcpros/master.h"

namespace moverl_tcpros {

ServiceClient::ServiceClient(std::string service, std::string md5sum, bool persistent)
    : name_(std::move(service)), md5_(std::move(md5sum)), persistent_(persistent) {}

bool ServiceClient::connectToService(SteadyClock::time_point deadline, std::string* error) {
  // The master is asked where the service is only when the last address fails (a restarted server has a new port).
  if (port_ != 0) {
    if (socket_.connect(host_, port_, deadline, error)) return true;
    if (SteadyClock::now() >= deadline) return false;
  }
  port_ = 0;
  std::string uri;
  if (!lookupService(name_, deadline, &uri, error)) {
    *error = "service " + name_ + " is not advertised (" + *error + ")";
    return false;
  }
  if (!splitRosrpcUri(uri, &host_, &port_)) {
    *error = "service " + name_ + " has an address that is not a rosrpc:// URI: " + uri;
    port_ = 0;
    return false;
  }
  return socket_.connect(host_, port_, deadline, error);
}

bool ServiceClient::open(SteadyClock::time_point deadline, std::string* error) {
  if (!connectToService(deadline, error)) return false;
  const HeaderFields fields = {{"callerid", ros::this_node::getName()},
                               {"service", name_},
                               {"md5sum", md5_},
                               {"persistent", persistent_ ? "1" : "0"}};
  HeaderFields answer;
  std::string why;
  const bool exchanged = socket_.writeHeader(fields, deadline) && socket_.readHeader(&answer, deadline, &why);
  if (!exchanged) {
    *error = "service " + name_ + ": no answer to the connection header (" +
             (why.empty() ? std::string(socket_.timedOut() ? "timed out" : "connection closed") : why) + ")";
  } else if (answer.count("error")) {
    *error = "service " + name_ + " refused the connection: " + answer["error"];
  } else if (md5_ != "*" && answer["md5sum"] != md5_) {
    // The server checks the md5sum we sent; a server that does not (or was replaced by one of another type) is caught
    // here, before any request is written.
    *error = "service " + name_ + " is of another type: its md5sum is [" + answer["md5sum"] + "], ours [" + md5_ + "]";
  } else {
    ++connections_;
    return true;
  }
  socket_.close();
  port_ = 0;  // perhaps no longer the service's address: ask the master next time
  return false;
}

CallEnd ServiceClient::notOpened(SteadyClock::time_point deadline) const {
  // Nothing was written: not advertised, refused, no connection (nothing to wait for), or no time left.
  return SteadyClock::now() >= deadline ? CallEnd::kTimedOut : CallEnd::kUnreachable;
}

CallEnd ServiceClient::answerLost(const std::string& what, std::string* error) {
  const bool timed_out = socket_.timedOut();
  socket_.close();  // a late answer must never be read as the next call's
  if (timed_out) {
    *error = "service " + name_ + " did not answer in time";
    return CallEnd::kTimedOut;
  }
  *error = "service " + name_ + " closed the connection while its answer was awaited (" + what +
           "): it may have served the request, which is not sent again";
  return CallEnd::kClosed;
}

CallEnd ServiceClient::call(const std::uint8_t* request, std::size_t n, SteadyClock::time_point deadline,
                            std::vector<std::uint8_t>* response, std::string* error) {
  error->clear();
  bool reused = false;
  if (socket_.isOpen()) {
    reused = socket_.idle();
    if (!reused) socket_.close();  // closed by the server while idle: the request is never written to it
  }
  if (!socket_.isOpen() && !open(deadline, error)) return notOpened(deadline);
  if (!socket_.writeAll(request, n, deadline)) {
    const bool timed_out = socket_.timedOut();
    socket_.close();
    if (timed_out) {
      *error = "service " + name_ + " did not take the request in time";
      return CallEnd::kTimedOut;
    }
    if (!reused) {
      *error = "service " + name_ + " closed a new connection before the request was written";
      return CallEnd::kUnreachable;
    }
    // The write failed on an idle persistent connection (closed by the server just now): the server did not get the
    // whole request, so it cannot have acted on it. The one case where a request is written again.
    if (!open(deadline, error)) return notOpened(deadline);
    if (!socket_.writeAll(request, n, deadline)) {
      const bool late = socket_.timedOut();
      socket_.close();
      *error = "service " + name_ + (late ? " did not take the request in time" : " closed a new connection");
      return late ? CallEnd::kTimedOut : CallEnd::kUnreachable;
    }
  }
  std::uint8_t head[5];
  if (!socket_.readAll(head, 5, deadline)) return answerLost("before the answer began", error);
  const std::uint32_t len = readLength(head + 1);
  if (len > kMaxMessageBytes) {  // not an answer of this service: the stream is out of step
    *error = "service " + name_ + " sent an answer of " + std::to_string(len) + " bytes";
    socket_.close();
    return CallEnd::kFailed;
  }
  response->resize(len);
  if (!socket_.readAll(response->data(), len, deadline)) return answerLost("the answer was cut short", error);
  if (head[0] != 1) {  // the server could not handle the request; its message is the payload
    *error = "service " + name_ + " failed: " + std::string(response->begin(), response->end());
    socket_.close();
    return CallEnd::kFailed;
  }
  if (!persistent_) socket_.close();
  return CallEnd::kAnswered;
}

}  // namespace moverl_tcpros
