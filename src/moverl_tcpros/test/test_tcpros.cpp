// moverl_tcpros on loopback sockets, against real peers: a ROS master of its own (rosmaster --core on a free port,
// started by main() and killed by pid at the end, also when the binary dies), rospy servers and clients
// (rospy_peer.py), roscpp servers and clients (ros::ServiceServer / ros::ServiceClient in this process, the
// tcpros_peer helper), `rosservice`, and raw TCPROS peers whose every byte a test decides. Both directions, persistent
// and not; header errors and wrong md5sums either way; a server that closes mid-answer; at most once; unregistration;
// the client cap; IPv6. Every test has a deadline (SIGALRM ends the binary: kTestSeconds).
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <moverl_msgs/ExecuteTrajectory.h>
#include <moverl_msgs/ResetRobot.h>
#include <ros/callback_queue.h>
#include <ros/ros.h>

#include "harness.h"
#include "moverl_tcpros/tcpros.h"

namespace moverl_tcpros {
/// gtest prints a CallEnd by its name.
void PrintTo(CallEnd end, std::ostream* os) { *os << callEndName(end); }
}  // namespace moverl_tcpros

namespace mt = moverl_tcpros;
using moverl_msgs::ExecuteTrajectory;
using moverl_msgs::ResetRobot;
using moverl_tcpros_test::Child;
using moverl_tcpros_test::RawPeer;
using moverl_tcpros_test::waitFor;

namespace {

constexpr unsigned kTestSeconds = 90;  // generous: the sanitizer builds run several times slower

void onAlarm(int) {
  const char m[] = "test_tcpros: a test outlived its deadline\n";
  (void)!::write(2, m, sizeof(m) - 1);
  ::_exit(3);
}

class PerTestDeadline : public ::testing::EmptyTestEventListener {
  void OnTestStart(const ::testing::TestInfo&) override { ::alarm(kTestSeconds); }
  void OnTestEnd(const ::testing::TestInfo&) override { ::alarm(0); }
};

std::string serviceName() {
  return "/tcpros_test/" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name());
}

std::string md5() { return ros::service_traits::md5sum<ExecuteTrajectory>(); }

std::unique_ptr<Child> rospyPeer(std::vector<std::string> args) {
  args.insert(args.begin(), {"/usr/bin/python3", std::string(TCPROS_TEST_DIR) + "/rospy_peer.py"});
  return std::make_unique<Child>(args);
}

/// A rospy server of `name`, up and registered.
std::unique_ptr<Child> rospyServer(const std::string& name) {
  auto server = rospyPeer({"server", name});
  std::string line;
  EXPECT_TRUE(server->readLine(&line, 30.0) && line == "ready") << line;
  return server;
}

/// The lines a rospy client prints for its calls.
std::vector<std::string> rospyCalls(const std::string& name, int calls, bool persistent, bool reset = false) {
  std::vector<std::string> args = {"client", name, std::to_string(calls), persistent ? "1" : "0"};
  if (reset) args.push_back("reset");
  auto client = rospyPeer(args);
  std::vector<std::string> lines;
  std::string line;
  while (client->readLine(&line, 30.0)) lines.push_back(line);
  EXPECT_EQ(client->wait(10.0), 0);
  return lines;
}

/// Our server of ExecuteTrajectory: answers "ours <n>" with state.position = [not_after]; fails when not_after < 0.
std::unique_ptr<mt::ServiceServer> ourServer(const std::string& name, std::atomic<int>* served,
                                             mt::ServerOptions options = mt::ServerOptions()) {
  return mt::advertiseDirect<ExecuteTrajectory>(
      name,
      [served](ExecuteTrajectory::Request& req, ExecuteTrajectory::Response& res) {
        if (req.not_after < 0) return false;
        res.message = "ours " + std::to_string(++*served);
        res.state.position = {req.not_after};
        return true;
      },
      options);
}

/// Where the master says `name` is ("" when nobody provides it).
std::string lookup(const std::string& name) {
  std::string uri, error;
  return mt::lookupService(name, mt::after(5.0), &uri, &error) ? uri : "";
}

/// A connected raw client of `name` that has exchanged headers (fields added to a valid request header).
int rawClient(const std::string& name, mt::HeaderFields extra, mt::HeaderFields* answer) {
  std::string host;
  std::uint32_t port = 0;
  if (!mt::splitRosrpcUri(lookup(name), &host, &port)) return -1;
  mt::Socket s;
  std::string error;
  if (!s.connect(host, port, mt::after(5.0), &error)) return -1;
  mt::HeaderFields fields = {{"callerid", "/raw"}, {"service", name}, {"md5sum", md5()}, {"persistent", "1"}};
  for (const auto& kv : extra) fields[kv.first] = kv.second;
  if (!RawPeer::writeHeader(s.fd(), fields) || !RawPeer::readHeader(s.fd(), answer)) return -1;
  const int fd = ::dup(s.fd());
  return fd;
}

/// An ExecuteTrajectory request, serialized with its length ([4-byte length][payload]).
std::vector<std::uint8_t> serializedRequest(double not_after) {
  ExecuteTrajectory::Request req;
  req.not_after = not_after;
  const ros::SerializedMessage m = ros::serialization::serializeMessage(req);
  return std::vector<std::uint8_t>(m.buf.get(), m.buf.get() + m.num_bytes);
}

std::vector<std::uint8_t> serializedResponse(const std::string& message) {
  ExecuteTrajectory::Response res;
  res.message = message;
  const ros::SerializedMessage m = ros::serialization::serializeMessage(res);
  return std::vector<std::uint8_t>(m.buf.get() + 4, m.buf.get() + m.num_bytes);  // without the length
}

/// A raw peer script that serves requests on its connection like a good server until the client leaves.
void serveWell(RawPeer* peer, int fd) {
  mt::HeaderFields h;
  if (!RawPeer::readHeader(fd, &h) || !RawPeer::writeHeader(fd, RawPeer::serverHeader(md5()))) return;
  std::vector<std::uint8_t> request;
  while (peer->readRequest(fd, &request)) {
    if (!RawPeer::writeAnswer(fd, true, serializedResponse("raw " + std::to_string(peer->requests.load())))) return;
  }
}

}  // namespace

// ------------------------------------------------------------------------------------------------------- wire format
TEST(Wire, HeaderRoundTripAndMalformedHeaders) {
  const mt::HeaderFields fields = {{"callerid", "/a"}, {"md5sum", "*"}, {"with", "an=equals sign"}, {"empty", ""}};
  const std::vector<std::uint8_t> body = mt::encodeHeader(fields);
  mt::HeaderFields back;
  std::string error;
  ASSERT_TRUE(mt::decodeHeader(body.data(), body.size(), &back, &error)) << error;
  EXPECT_EQ(back, fields);
  EXPECT_FALSE(mt::decodeHeader(body.data(), body.size() - 1, &back, &error));  // the last field runs past the end
  EXPECT_NE(error.find("runs past"), std::string::npos) << error;
  const std::vector<std::uint8_t> no_equals = {3, 0, 0, 0, 'a', 'b', 'c'};
  EXPECT_FALSE(mt::decodeHeader(no_equals.data(), no_equals.size(), &back, &error));
  const std::vector<std::uint8_t> short_length = {3, 0};
  EXPECT_FALSE(mt::decodeHeader(short_length.data(), short_length.size(), &back, &error));
}

TEST(Wire, RosrpcUris) {
  std::string host;
  std::uint32_t port = 0;
  ASSERT_TRUE(mt::splitRosrpcUri("rosrpc://127.0.0.1:4567", &host, &port));
  EXPECT_EQ(host, "127.0.0.1");
  EXPECT_EQ(port, 4567u);
  ASSERT_TRUE(mt::splitRosrpcUri("rosrpc://[::1]:80/", &host, &port));
  EXPECT_EQ(host, "::1");
  EXPECT_EQ(port, 80u);
  ASSERT_TRUE(mt::splitRosrpcUri("rosrpc://robot-pc:12/", &host, &port));
  EXPECT_EQ(host, "robot-pc");
  for (const char* bad : {"http://a:1", "rosrpc://a", "rosrpc://a:", "rosrpc://a:0", "rosrpc://a:70000",
                          "rosrpc://a:1x", "rosrpc://[::1:5", "rosrpc://:5"}) {
    EXPECT_FALSE(mt::splitRosrpcUri(bad, &host, &port)) << bad;
  }
  EXPECT_EQ(mt::rosrpcUri("::1", 5), "rosrpc://[::1]:5");
  EXPECT_EQ(mt::rosrpcUri("localhost", 5), "rosrpc://localhost:5");
}

// ------------------------------------------------------------------------------------------------- our client calls
TEST(Client, CallsRospyServerPersistentAndNot) {
  const std::string name = serviceName();
  auto server = rospyServer(name);
  int expected = 0;
  for (bool persistent : {true, false}) {
    mt::DirectServiceClient<ExecuteTrajectory> client(name, persistent);
    for (int i = 0; i < 3; ++i) {
      ExecuteTrajectory srv;
      srv.request.not_after = 0.25 + i;
      ASSERT_EQ(client.call(srv, 10.0), mt::CallEnd::kAnswered) << client.error();
      EXPECT_EQ(srv.response.message, "rospy " + std::to_string(++expected));
      ASSERT_EQ(srv.response.state.position.size(), 1u);
      EXPECT_EQ(srv.response.state.position[0], 0.25 + i);
    }
    EXPECT_EQ(client.connections(), persistent ? 1u : 3u);
  }
  // The handler fails: an error answer, reported as such (not as an unreachable server).
  mt::DirectServiceClient<ExecuteTrajectory> client(name);
  ExecuteTrajectory failing;
  failing.request.not_after = -1.0;
  EXPECT_EQ(client.call(failing, 10.0), mt::CallEnd::kFailed);
  EXPECT_NE(client.error().find("asked to fail"), std::string::npos) << client.error();
  // A client of another type: rospy refuses it at the header (md5sum in our header), nothing is served.
  mt::DirectServiceClient<ResetRobot> wrong(name);
  ResetRobot reset;
  EXPECT_EQ(wrong.call(reset, 10.0), mt::CallEnd::kUnreachable);
  EXPECT_NE(wrong.error().find("md5sums do not match"), std::string::npos) << wrong.error();
  server->closeStdin();
  std::string line;
  ASSERT_TRUE(server->readLine(&line, 10.0));
  EXPECT_EQ(line, "served 6");
}

TEST(Client, CallsRoscppServerPersistentAndNot) {
  const std::string name = serviceName();
  ros::NodeHandle nh;
  ros::CallbackQueue queue;
  nh.setCallbackQueue(&queue);
  std::atomic<int> served{0};
  ros::ServiceServer server = nh.advertiseService<ExecuteTrajectory::Request, ExecuteTrajectory::Response>(
      name, [&served](ExecuteTrajectory::Request& req, ExecuteTrajectory::Response& res) {
        if (req.not_after < 0) return false;
        res.message = "roscpp " + std::to_string(++served);
        res.state.position = {req.not_after};
        return true;
      });
  ros::AsyncSpinner spinner(1, &queue);
  spinner.start();
  int expected = 0;
  for (bool persistent : {true, false}) {
    mt::DirectServiceClient<ExecuteTrajectory> client(name, persistent);
    for (int i = 0; i < 3; ++i) {
      ExecuteTrajectory srv;
      srv.request.not_after = 0.5 + i;
      ASSERT_EQ(client.call(srv, 10.0), mt::CallEnd::kAnswered) << client.error();
      EXPECT_EQ(srv.response.message, "roscpp " + std::to_string(++expected));
      ASSERT_EQ(srv.response.state.position.size(), 1u);
      EXPECT_EQ(srv.response.state.position[0], 0.5 + i);
    }
    EXPECT_EQ(client.connections(), persistent ? 1u : 3u);
  }
  mt::DirectServiceClient<ExecuteTrajectory> client(name);
  ExecuteTrajectory failing;
  failing.request.not_after = -1.0;
  EXPECT_EQ(client.call(failing, 10.0), mt::CallEnd::kFailed) << client.error();
  // roscpp refuses a client of another type at the header.
  mt::DirectServiceClient<ResetRobot> wrong(name);
  ResetRobot reset;
  EXPECT_EQ(wrong.call(reset, 10.0), mt::CallEnd::kUnreachable);
  EXPECT_NE(wrong.error().find("md5sum"), std::string::npos) << wrong.error();
  EXPECT_EQ(served.load(), 6);
  spinner.stop();
}

TEST(Client, UnadvertisedServiceIsUnreachable) {
  mt::DirectServiceClient<ExecuteTrajectory> client(serviceName());
  ExecuteTrajectory srv;
  EXPECT_EQ(client.call(srv, 5.0), mt::CallEnd::kUnreachable);
  EXPECT_NE(client.error().find("not advertised"), std::string::npos) << client.error();
}

// ------------------------------------------------------------------------------------------------- our server serves
TEST(Server, ServesRospyClientsPersistentAndNot) {
  const std::string name = serviceName();
  std::atomic<int> served{0};
  auto server = ourServer(name, &served);
  for (bool persistent : {true, false}) {
    const int before = served.load();
    const std::vector<std::string> lines = rospyCalls(name, 3, persistent);
    ASSERT_EQ(lines.size(), 3u);
    for (int i = 0; i < 3; ++i) {
      EXPECT_EQ(lines[i], "answer ours " + std::to_string(before + i + 1) + " " + std::to_string(i) + ".5");
    }
  }
  // A rospy client of another type is refused at the header; nothing is served.
  const std::vector<std::string> wrong = rospyCalls(name, 1, false, true);
  ASSERT_EQ(wrong.size(), 1u);
  EXPECT_EQ(wrong[0].rfind("error", 0), 0u) << wrong[0];
  EXPECT_NE(wrong[0].find("md5sums do not match"), std::string::npos) << wrong[0];
  EXPECT_EQ(served.load(), 6);
  // rosservice (rospy's tools) probes for the type.
  Child rosservice({"rosservice", "type", name});
  std::string line;
  ASSERT_TRUE(rosservice.readLine(&line, 30.0));
  EXPECT_EQ(line, "moverl_msgs/ExecuteTrajectory");
  EXPECT_EQ(rosservice.wait(10.0), 0);
}

TEST(Server, ServesRoscppClientsPersistentAndNot) {
  const std::string name = serviceName();
  std::atomic<int> served{0};
  auto server = ourServer(name, &served);
  ros::NodeHandle nh;
  EXPECT_TRUE(ros::service::exists(name, false));  // a probe connection
  for (bool persistent : {true, false}) {
    ros::ServiceClient client = nh.serviceClient<ExecuteTrajectory>(name, persistent);
    for (int i = 0; i < 3; ++i) {
      const int before = served.load();
      ExecuteTrajectory srv;
      srv.request.not_after = 2.0 + i;
      ASSERT_TRUE(client.call(srv));
      EXPECT_EQ(srv.response.message, "ours " + std::to_string(before + 1));
      ASSERT_EQ(srv.response.state.position.size(), 1u);
      EXPECT_EQ(srv.response.state.position[0], 2.0 + i);
    }
  }
  ExecuteTrajectory failing;
  failing.request.not_after = -1.0;
  EXPECT_FALSE(ros::service::call(name, failing));
  ros::ServiceClient wrong = nh.serviceClient<ResetRobot>(name);
  ResetRobot reset;
  EXPECT_FALSE(wrong.call(reset));  // refused at the header: md5sums differ
  EXPECT_EQ(served.load(), 6);
  // Our own client too, persistent and not.
  for (bool persistent : {true, false}) {
    mt::DirectServiceClient<ExecuteTrajectory> ours(name, persistent);
    for (int i = 0; i < 2; ++i) {
      ExecuteTrajectory srv;
      ASSERT_EQ(ours.call(srv, 10.0), mt::CallEnd::kAnswered) << ours.error();
    }
    EXPECT_EQ(ours.connections(), persistent ? 1u : 2u);
  }
  EXPECT_EQ(served.load(), 10);
}

TEST(Server, RefusesBadHeadersWithAnErrorHeader) {
  const std::string name = serviceName();
  std::atomic<int> served{0};
  auto server = ourServer(name, &served);
  std::string host;
  std::uint32_t port = 0;
  ASSERT_TRUE(mt::splitRosrpcUri(server->uri(), &host, &port));
  struct Case {
    const char* what;
    std::vector<std::uint8_t> header;  // the whole header as sent, with its length
    const char* expected;              // in the error field of the answer
  };
  auto framed = [](const mt::HeaderFields& f) {
    const std::vector<std::uint8_t> body = mt::encodeHeader(f);
    std::vector<std::uint8_t> out(4 + body.size());
    const std::uint32_t n = static_cast<std::uint32_t>(body.size());
    std::memcpy(out.data(), &n, 4);
    std::copy(body.begin(), body.end(), out.begin() + 4);
    return out;
  };
  const std::vector<Case> cases = {
      {"wrong md5sum", framed({{"callerid", "/x"}, {"service", name}, {"md5sum", std::string(32, '0')}}),
       "md5sums do not match"},
      {"no md5sum", framed({{"callerid", "/x"}, {"service", name}}), "no md5sum"},
      {"another service", framed({{"callerid", "/x"}, {"service", "/elsewhere"}, {"md5sum", "*"}}), "not '/elsewhere'"},
      {"no service", framed({{"callerid", "/x"}, {"md5sum", "*"}}), "not ''"},
      {"a field without '='", {7, 0, 0, 0, 3, 0, 0, 0, 'a', 'b', 'c'}, "without '='"},
      {"a field running past the end", {8, 0, 0, 0, 9, 0, 0, 0, 'a', '=', 'b', 'c'}, "runs past"},
      {"a header of 16 MB", {0, 0, 0, 1}, "bytes"},
  };
  for (const Case& c : cases) {
    mt::Socket s;
    std::string error;
    ASSERT_TRUE(s.connect(host, port, mt::after(5.0), &error)) << error;
    ASSERT_TRUE(RawPeer::writeRaw(s.fd(), c.header)) << c.what;
    mt::HeaderFields answer;
    ASSERT_TRUE(RawPeer::readHeader(s.fd(), &answer)) << c.what;
    ASSERT_EQ(answer.count("error"), 1u) << c.what;
    EXPECT_NE(answer["error"].find(c.expected), std::string::npos) << c.what << ": " << answer["error"];
    EXPECT_FALSE(RawPeer::sendsMore(s.fd(), 5.0)) << c.what;  // then closed
  }
  EXPECT_EQ(served.load(), 0);
  // A probe gets the type and is closed.
  mt::HeaderFields answer;
  const int probe = rawClient(name, {{"probe", "1"}, {"md5sum", "*"}}, &answer);
  ASSERT_GE(probe, 0);
  EXPECT_EQ(answer["type"], "moverl_msgs/ExecuteTrajectory");
  EXPECT_EQ(answer["md5sum"], md5());
  EXPECT_FALSE(RawPeer::sendsMore(probe, 5.0));
  ::close(probe);
}

TEST(Server, DropsCutShortAndCorruptRequestsOnly) {
  const std::string name = serviceName();
  std::atomic<int> served{0};
  auto server = ourServer(name, &served);
  mt::HeaderFields answer;
  const std::vector<std::uint8_t> request = serializedRequest(1.0);
  // A request cut short (the client leaves half-way).
  int fd = rawClient(name, {}, &answer);
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(RawPeer::writeRaw(fd, std::vector<std::uint8_t>(request.begin(), request.begin() + 10)));
  ::close(fd);
  // A corrupt length (4 GB): dropped without an answer.
  fd = rawClient(name, {}, &answer);
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(RawPeer::writeRaw(fd, {0xf0, 0xff, 0xff, 0xff, 0, 0, 0, 0}));
  EXPECT_FALSE(RawPeer::sendsMore(fd, 5.0));
  ::close(fd);
  // The server serves the next client.
  mt::DirectServiceClient<ExecuteTrajectory> client(name);
  ExecuteTrajectory srv;
  ASSERT_EQ(client.call(srv, 10.0), mt::CallEnd::kAnswered) << client.error();
  EXPECT_EQ(served.load(), 1);
}

// ------------------------------------------------------------------------------- our client against raw server peers
TEST(Client, ChecksTheServersHeader) {
  const std::string name = serviceName();
  struct Case {
    const char* what;
    mt::HeaderFields header;
    const char* expected;
  };
  const std::vector<Case> cases = {
      {"a wrong md5sum", RawPeer::serverHeader(std::string(32, 'f')), "another type"},
      {"no md5sum", {{"callerid", "/raw_peer"}, {"type", "moverl_msgs/ExecuteTrajectory"}}, "another type"},
      {"an error", {{"error", "we do not serve you"}}, "we do not serve you"},
  };
  for (const Case& c : cases) {
    std::atomic<bool> more{true};
    RawPeer peer(name, [&](int fd) {
      mt::HeaderFields h;
      if (RawPeer::readHeader(fd, &h) && RawPeer::writeHeader(fd, c.header)) more = RawPeer::sendsMore(fd, 2.0);
    });
    mt::DirectServiceClient<ExecuteTrajectory> client(name);
    ExecuteTrajectory srv;
    EXPECT_EQ(client.call(srv, 5.0), mt::CallEnd::kUnreachable) << c.what;
    EXPECT_NE(client.error().find(c.expected), std::string::npos) << c.what << ": " << client.error();
    ASSERT_TRUE(waitFor([&] { return peer.closed.load() == 1; }, 5.0)) << c.what;
    EXPECT_FALSE(more.load()) << c.what << ": the client wrote a request after a bad header";
    EXPECT_EQ(peer.requests.load(), 0) << c.what;
  }
  // A malformed header, and none at all.
  for (bool malformed : {true, false}) {
    RawPeer peer(name, [&](int fd) {
      mt::HeaderFields h;
      if (RawPeer::readHeader(fd, &h) && malformed) RawPeer::writeRaw(fd, {4, 0, 0, 0, 1, 0, 0, 0});
    });
    mt::DirectServiceClient<ExecuteTrajectory> client(name);
    ExecuteTrajectory srv;
    EXPECT_EQ(client.call(srv, 5.0), mt::CallEnd::kUnreachable);
    EXPECT_NE(client.error().find("connection header"), std::string::npos) << client.error();
  }
}

TEST(Client, ReportsAServerThatClosesMidAnswer) {
  const std::string name = serviceName();
  for (bool reset : {false, true}) {
    RawPeer peer(name, [&](int fd) {
      mt::HeaderFields h;
      std::vector<std::uint8_t> request;
      if (!RawPeer::readHeader(fd, &h) || !RawPeer::writeHeader(fd, RawPeer::serverHeader(md5())) ||
          !peer.readRequest(fd, &request)) {
        return;
      }
      std::vector<std::uint8_t> answer = {1, 100, 0, 0, 0};  // 100 bytes announced, 50 sent
      answer.resize(5 + 50, 'x');
      RawPeer::writeRaw(fd, answer);
      if (reset) RawPeer::resetClose(fd);
    });
    mt::DirectServiceClient<ExecuteTrajectory> client(name);
    ExecuteTrajectory srv;
    EXPECT_EQ(client.call(srv, 10.0), mt::CallEnd::kClosed) << client.error();
    EXPECT_NE(client.error().find("cut short"), std::string::npos) << client.error();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    EXPECT_EQ(peer.requests.load(), 1);  // not sent again
    EXPECT_EQ(peer.connections.load(), 1);
  }
}

TEST(Client, SendsARequestAtMostOnce) {
  // The server reads the request and closes without a word (with a FIN, then with a reset): the call reports the
  // closed connection and never sends the request again; the server counts one request.
  const std::string name = serviceName();
  for (bool reset : {false, true}) {
    RawPeer peer(name, [&](int fd) {
      mt::HeaderFields h;
      std::vector<std::uint8_t> request;
      if (!RawPeer::readHeader(fd, &h) || !RawPeer::writeHeader(fd, RawPeer::serverHeader(md5()))) return;
      if (peer.requests.load() == 0) {
        peer.readRequest(fd, &request);
        if (reset) RawPeer::resetClose(fd);
        return;
      }
      while (peer.readRequest(fd, &request)) RawPeer::writeAnswer(fd, true, serializedResponse("second"));
    });
    mt::DirectServiceClient<ExecuteTrajectory> client(name);
    ExecuteTrajectory srv;
    EXPECT_EQ(client.call(srv, 10.0), mt::CallEnd::kClosed) << client.error();
    EXPECT_NE(client.error().find("not sent again"), std::string::npos) << client.error();
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    EXPECT_EQ(peer.requests.load(), 1) << (reset ? "reset" : "FIN");
    EXPECT_EQ(peer.connections.load(), 1) << (reset ? "reset" : "FIN");
    // The caller's next request is a new one, on a new connection.
    ASSERT_EQ(client.call(srv, 10.0), mt::CallEnd::kAnswered) << client.error();
    EXPECT_EQ(srv.response.message, "second");
    EXPECT_EQ(peer.requests.load(), 2);
    EXPECT_EQ(client.connections(), 2u);
  }
}

TEST(Client, TimesOutWithoutResending) {
  const std::string name = serviceName();
  std::atomic<bool> release{false};
  RawPeer peer(name, [&](int fd) {
    mt::HeaderFields h;
    std::vector<std::uint8_t> request;
    if (!RawPeer::readHeader(fd, &h) || !RawPeer::writeHeader(fd, RawPeer::serverHeader(md5()))) return;
    peer.readRequest(fd, &request);
    waitFor([&] { return release.load(); }, 10.0);  // never answers
  });
  mt::DirectServiceClient<ExecuteTrajectory> client(name);
  ExecuteTrajectory srv;
  const auto t0 = mt::SteadyClock::now();
  EXPECT_EQ(client.call(srv, 0.3), mt::CallEnd::kTimedOut) << client.error();
  const double took = std::chrono::duration<double>(mt::SteadyClock::now() - t0).count();
  EXPECT_GE(took, 0.3);
  EXPECT_LT(took, 1.5);
  release = true;
  ASSERT_TRUE(waitFor([&] { return peer.closed.load() == 1; }, 5.0));
  EXPECT_EQ(peer.requests.load(), 1);
  EXPECT_EQ(peer.connections.load(), 1);
}

TEST(Client, SendsOnANewConnectionWhenTheIdleOneWasClosed) {
  // The server answers, then closes the idle persistent connection (FIN, then reset): the next request was never
  // written to it, so it goes over a new connection and is answered. One request per call.
  const std::string name = serviceName();
  for (bool reset : {false, true}) {
    RawPeer peer(name, [&](int fd) {
      mt::HeaderFields h;
      std::vector<std::uint8_t> request;
      if (!RawPeer::readHeader(fd, &h) || !RawPeer::writeHeader(fd, RawPeer::serverHeader(md5())) ||
          !peer.readRequest(fd, &request)) {
        return;
      }
      RawPeer::writeAnswer(fd, true, serializedResponse("answered " + std::to_string(peer.requests.load())));
      if (reset) RawPeer::resetClose(fd);
    });
    mt::DirectServiceClient<ExecuteTrajectory> client(name);
    for (int i = 1; i <= 3; ++i) {
      ASSERT_TRUE(waitFor([&] { return peer.closed.load() == i - 1; }, 5.0));
      std::this_thread::sleep_for(std::chrono::milliseconds(50));  // the close reaches the client
      ExecuteTrajectory srv;
      ASSERT_EQ(client.call(srv, 10.0), mt::CallEnd::kAnswered) << client.error();
      EXPECT_EQ(srv.response.message, "answered " + std::to_string(i));
    }
    EXPECT_EQ(peer.requests.load(), 3);
    EXPECT_EQ(client.connections(), 3u);
  }
  // A real rospy server restarted (on another port): the next call finds it through the master.
  auto server = rospyServer(name);
  mt::DirectServiceClient<ExecuteTrajectory> client(name);
  ExecuteTrajectory srv;
  ASSERT_EQ(client.call(srv, 10.0), mt::CallEnd::kAnswered) << client.error();
  server->signal(SIGKILL);
  server->wait(5.0);
  server = rospyServer(name);
  ASSERT_EQ(client.call(srv, 10.0), mt::CallEnd::kAnswered) << client.error();
  EXPECT_EQ(srv.response.message, "rospy 1");
  EXPECT_EQ(client.connections(), 2u);
}

// ------------------------------------------------------------------------------------- registration, cap, addresses
TEST(Server, UnregistersOnDestruction) {
  const std::string name = serviceName();
  std::atomic<int> served{0};
  auto server = ourServer(name, &served);
  EXPECT_EQ(lookup(name), server->uri());
  server.reset();
  EXPECT_EQ(lookup(name), "");
}

TEST(Server, UnregistersAfterRosShutdown) {
  // A node that roscpp shut down first (the master's shutdown call, a signal roscpp handles): the server destroyed
  // afterwards still unregisters (tcpros_peer, a roscpp process of its own).
  const std::string name = serviceName();
  Child peer({TCPROS_PEER, "shutdown_first", name});
  std::string line;
  ASSERT_TRUE(peer.readLine(&line, 30.0));
  ASSERT_EQ(line.rfind("ready ", 0), 0u) << line;
  EXPECT_EQ(lookup(name), line.substr(6));
  peer.writeLine("go");
  ASSERT_TRUE(peer.readLine(&line, 30.0));
  EXPECT_EQ(line, "destroyed");
  EXPECT_EQ(peer.wait(10.0), 0);
  EXPECT_EQ(lookup(name), "");
}

TEST(Server, CapsItsClients) {
  const std::string name = serviceName();
  std::atomic<int> served{0};
  mt::ServerOptions options;
  options.max_clients = 2;
  auto server = ourServer(name, &served, options);
  mt::HeaderFields answer;
  const int a = rawClient(name, {}, &answer), b = rawClient(name, {}, &answer);
  ASSERT_GE(a, 0);
  ASSERT_GE(b, 0);
  ASSERT_TRUE(waitFor([&] { return server->clients() == 2; }, 5.0));
  // A third client gets an error header, then the end of the stream.
  const int c = rawClient(name, {}, &answer);
  ASSERT_GE(c, 0);
  EXPECT_NE(answer["error"].find("at most 2 clients"), std::string::npos) << answer["error"];
  EXPECT_FALSE(RawPeer::sendsMore(c, 5.0));
  ::close(c);
  // So do real clients.
  mt::DirectServiceClient<ExecuteTrajectory> ours(name);
  ExecuteTrajectory srv;
  EXPECT_EQ(ours.call(srv, 5.0), mt::CallEnd::kUnreachable);
  EXPECT_NE(ours.error().find("at most 2 clients"), std::string::npos) << ours.error();
  const std::vector<std::string> rospy = rospyCalls(name, 1, false);
  ASSERT_EQ(rospy.size(), 1u);
  EXPECT_NE(rospy[0].find("at most 2 clients"), std::string::npos) << rospy[0];
  EXPECT_EQ(served.load(), 0);
  // A client leaves: the next one is served.
  ::close(a);
  ASSERT_TRUE(waitFor([&] { return server->clients() == 1; }, 5.0));
  ASSERT_EQ(ours.call(srv, 5.0), mt::CallEnd::kAnswered) << ours.error();
  EXPECT_EQ(served.load(), 1);
  ::close(b);
}

TEST(Server, ListensOnIpv6WhereItsHostResolvesToIt) {
  const std::string name = serviceName();
  std::atomic<int> served{0};
  mt::ServerOptions options;
  options.host = "::1";
  auto server = ourServer(name, &served, options);
  std::string host;
  std::uint32_t port = 0;
  ASSERT_TRUE(mt::splitRosrpcUri(server->uri(), &host, &port)) << server->uri();
  EXPECT_EQ(server->uri(), "rosrpc://[::1]:" + std::to_string(port));
  mt::Socket v4;
  std::string error;
  EXPECT_FALSE(v4.connect("127.0.0.1", port, mt::after(5.0), &error));  // IPv6 only
  mt::DirectServiceClient<ExecuteTrajectory> client(name);              // through the master, over IPv6
  ExecuteTrajectory srv;
  ASSERT_EQ(client.call(srv, 10.0), mt::CallEnd::kAnswered) << client.error();
  EXPECT_EQ(served.load(), 1);
}

TEST(Server, DestructionEndsIdleConnectionsAtOnce) {
  const std::string name = serviceName();
  std::atomic<int> served{0};
  auto server = ourServer(name, &served);
  mt::HeaderFields answer;
  const int fd = rawClient(name, {}, &answer);
  ASSERT_GE(fd, 0);
  ASSERT_TRUE(waitFor([&] { return server->clients() == 1; }, 5.0));
  const auto t0 = mt::SteadyClock::now();
  server.reset();
  EXPECT_LT(std::chrono::duration<double>(mt::SteadyClock::now() - t0).count(), 1.0);
  EXPECT_FALSE(RawPeer::sendsMore(fd, 5.0));
  ::close(fd);
}

// --------------------------------------------------------------------------------------------------------------- main
int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ::signal(SIGALRM, onAlarm);
  ::testing::UnitTest::GetInstance()->listeners().Append(new PerTestDeadline);
  // A master of our own, on a free loopback port (never 11311, never a running graph's); every peer uses it.
  const std::string port = std::to_string(moverl_tcpros_test::freePort());
  ::setenv("ROS_MASTER_URI", ("http://127.0.0.1:" + port).c_str(), 1);
  ::setenv("ROS_HOSTNAME", "127.0.0.1", 1);
  ::unsetenv("ROS_IP");
  ::alarm(kTestSeconds);  // the set-up has a deadline too
  ros::init(argc, argv, "tcpros_test", ros::init_options::NoSigintHandler);
  int rc = 1;
  {
    Child master({"rosmaster", "--core", "-p", port, "-w", "3"});
    XmlRpc::XmlRpcValue params, pid;
    params[0] = "/tcpros_test";
    std::string error;
    const bool up = waitFor([&] { return mt::callMaster("getPid", params, &pid, mt::after(1.0), &error); }, 60.0);
    if (!up) {
      std::fprintf(stderr, "test_tcpros: the master did not come up: %s\n", error.c_str());
    } else {
      ros::start();
      ::alarm(0);
      rc = RUN_ALL_TESTS();
      ros::shutdown();
    }
    master.signal(SIGINT);
    if (master.wait(10.0) < 0) std::fprintf(stderr, "test_tcpros: the master was killed (SIGKILL)\n");
  }
  return rc;
}
