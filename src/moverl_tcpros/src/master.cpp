#include "moverl_tcpros/master.h"

#include <xmlrpcpp/XmlRpcClient.h>

#include <ros/master.h>
#include <ros/this_node.h>

namespace moverl_tcpros {
namespace {

double secondsUntil(SteadyClock::time_point deadline) {
  return std::chrono::duration<double>(deadline - SteadyClock::now()).count();
}

}  // namespace

bool callMaster(const std::string& method, const XmlRpc::XmlRpcValue& params, XmlRpc::XmlRpcValue* value,
                SteadyClock::time_point deadline, std::string* error) {
  const std::string where = "the master at " + ros::master::getURI();
  // A client of its own per call (XmlRpcClient is not thread-safe; master calls are rare: registration, shutdown, a
  // service's address after its last one failed). XmlRpcClient::execute waits without a bound; executeNonBlock and
  // the client's own dispatcher (_disp, public in XmlRpc++) wait until the deadline.
  XmlRpc::XmlRpcClient client(ros::master::getHost().c_str(), static_cast<int>(ros::master::getPort()), "/");
  if (!client.executeNonBlock(method.c_str(), params)) {
    *error = "cannot reach " + where;
    return false;
  }
  XmlRpc::XmlRpcValue result;
  const double left = secondsUntil(deadline);
  // work() returns once the answer is read (done), the connection failed (done, with no answer) or the time is up.
  if (left > 0.0) client._disp.work(left);
  if (left <= 0.0 || !client.executeCheckDone(result)) {
    *error = where + " did not answer " + method + " in time";
    return false;
  }
  if (client.isFault() || result.getType() != XmlRpc::XmlRpcValue::TypeArray || result.size() != 3 ||
      result[0].getType() != XmlRpc::XmlRpcValue::TypeInt) {
    *error = where + " gave no answer to " + method + " (is it running?)";
    return false;
  }
  if (static_cast<int>(result[0]) != 1) {
    *error = method + ": " +
             (result[1].getType() == XmlRpc::XmlRpcValue::TypeString ? static_cast<std::string>(result[1])
                                                                     : std::string("failed"));
    return false;
  }
  *value = result[2];
  return true;
}

bool lookupService(const std::string& service, SteadyClock::time_point deadline, std::string* uri, std::string* error) {
  XmlRpc::XmlRpcValue params, value;
  params[0] = ros::this_node::getName();
  params[1] = service;
  if (!callMaster("lookupService", params, &value, deadline, error)) return false;
  if (value.getType() != XmlRpc::XmlRpcValue::TypeString) {
    *error = "lookupService: the master's answer is not a URI";
    return false;
  }
  *uri = static_cast<std::string>(value);
  return true;
}

bool lookupNode(const std::string& node, SteadyClock::time_point deadline, std::string* uri, std::string* error) {
  XmlRpc::XmlRpcValue params, value;
  params[0] = ros::this_node::getName();
  params[1] = node;
  if (!callMaster("lookupNode", params, &value, deadline, error)) return false;
  if (value.getType() != XmlRpc::XmlRpcValue::TypeString) {
    *error = "lookupNode: the master's answer is not a URI";
    return false;
  }
  *uri = static_cast<std::string>(value);
  return true;
}

}  // namespace moverl_tcpros
