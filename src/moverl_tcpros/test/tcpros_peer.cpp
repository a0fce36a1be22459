// A roscpp process for test_tcpros: a node that serves a moverl_tcpros service and is shut down in the order a test
// asks for.
//
//   tcpros_peer shutdown_first <service>
//     Serve <service> (moverl_msgs/ExecuteTrajectory), print "ready <uri>", wait for a line on stdin, then call
//     ros::shutdown() before the server is destroyed (what happens when roscpp shuts a node down by itself, e.g. on
//     the master's XML-RPC shutdown), and print "destroyed".
#include <cstdio>
#include <iostream>
#include <string>

#include <moverl_msgs/ExecuteTrajectory.h>
#include <ros/ros.h>

#include "moverl_tcpros/server.h"

int main(int argc, char** argv) {
  ros::init(argc, argv, "tcpros_peer", ros::init_options::AnonymousName | ros::init_options::NoSigintHandler);
  if (argc != 3 || std::string(argv[1]) != "shutdown_first") {
    std::fprintf(stderr, "usage: tcpros_peer shutdown_first <service>\n");
    return 2;
  }
  ros::NodeHandle nh;
  auto server = moverl_tcpros::advertiseDirect<moverl_msgs::ExecuteTrajectory>(
      argv[2], [](moverl_msgs::ExecuteTrajectory::Request&, moverl_msgs::ExecuteTrajectory::Response& res) {
        res.message = "tcpros_peer";
        return true;
      });
  std::cout << "ready " << server->uri() << std::endl;
  std::string line;
  std::getline(std::cin, line);
  ros::shutdown();
  server.reset();
  std::cout << "destroyed" << std::endl;
  return 0;
}
