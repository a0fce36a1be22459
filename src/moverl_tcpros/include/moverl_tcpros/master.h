// The ROS master's XML-RPC API (wiki.ros.org/ROS/Master_API), called with a deadline over a connection of its own:
// no roscpp internals, and it works before and after ros::shutdown() alike (the master's address and the node's name
// are fixed by ros::init).
#pragma once

#include <string>

#include <xmlrpcpp/XmlRpcValue.h>

#include "moverl_tcpros/call_end.h"

namespace moverl_tcpros {

/// \brief Call `method` on the master with `params` (the caller id first). *value gets the answer's value when its
///        status code is 1 (success); otherwise false with *error (no answer by the deadline, a fault, another code).
bool callMaster(const std::string& method, const XmlRpc::XmlRpcValue& params, XmlRpc::XmlRpcValue* value,
                SteadyClock::time_point deadline, std::string* error);

/// \brief The rosrpc:// URI of `service` (resolved name). False with *error when nobody provides it or the master
///        did not answer.
bool lookupService(const std::string& service, SteadyClock::time_point deadline, std::string* uri, std::string* error);

/// \brief The XML-RPC URI of `node` (resolved name). False with *error when the master does not know it.
bool lookupNode(const std::string& node, SteadyClock::time_point deadline, std::string* uri, std::string* error);

}  // namespace moverl_tcpros
