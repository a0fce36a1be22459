#include "harness.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>

#include <ros/this_node.h>

#include "moverl_tcpros/master.h"

namespace moverl_tcpros_test {
namespace mt = moverl_tcpros;
namespace {

int msLeft(mt::SteadyClock::time_point deadline) {
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - mt::SteadyClock::now()).count();
  return ms < 0 ? 0 : static_cast<int>(ms);
}

/// Read exactly n bytes from a blocking socket within 5 s.
bool recvAll(int fd, std::uint8_t* data, std::size_t n) {
  const auto deadline = mt::after(5.0);
  while (n > 0) {
    pollfd p{fd, POLLIN, 0};
    if (::poll(&p, 1, msLeft(deadline)) <= 0) return false;
    const ssize_t k = ::recv(fd, data, n, 0);
    if (k <= 0) return false;
    data += k;
    n -= static_cast<std::size_t>(k);
  }
  return true;
}

}  // namespace

// ------------------------------------------------------------------------------------------------------------ Child
Child::Child(const std::vector<std::string>& argv) {
  int in[2], out[2];
  if (::pipe2(in, O_CLOEXEC) < 0 || ::pipe2(out, O_CLOEXEC) < 0) throw std::runtime_error("pipe2 failed");
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const pid_t parent = ::getpid();
  pid_ = ::fork();
  if (pid_ < 0) throw std::runtime_error("fork failed");
  if (pid_ == 0) {  // only async-signal-safe calls until exec
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(126);
    ::dup2(in[0], 0);
    ::dup2(out[1], 1);
    for (int fd = 3; fd < 4096; ++fd) ::close(fd);  // no socket of ours stays open in the child
    ::execvp(args[0], args.data());
    ::_exit(127);
  }
  ::close(in[0]);
  ::close(out[1]);
  in_ = in[1];
  out_ = out[0];
}

Child::~Child() {
  if (!reaped_) {
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, &status_, 0);
  }
  if (in_ >= 0) ::close(in_);
  ::close(out_);
}

bool Child::readLine(std::string* line, double timeout) {
  const auto deadline = mt::after(timeout);
  for (;;) {
    const std::size_t nl = buffer_.find('\n');
    if (nl != std::string::npos) {
      *line = buffer_.substr(0, nl);
      buffer_.erase(0, nl + 1);
      return true;
    }
    pollfd p{out_, POLLIN, 0};
    if (::poll(&p, 1, msLeft(deadline)) <= 0) return false;
    char chunk[4096];
    const ssize_t n = ::read(out_, chunk, sizeof(chunk));
    if (n <= 0) return false;
    buffer_.append(chunk, static_cast<std::size_t>(n));
  }
}

void Child::closeStdin() {
  if (in_ >= 0) ::close(in_);
  in_ = -1;
}

void Child::writeLine(const std::string& line) {
  const std::string s = line + "\n";
  if (in_ >= 0) (void)!::write(in_, s.data(), s.size());
}

void Child::signal(int sig) { ::kill(pid_, sig); }

int Child::wait(double timeout) {
  if (reaped_) return status_;
  const auto deadline = mt::after(timeout);
  for (;;) {
    const pid_t r = ::waitpid(pid_, &status_, WNOHANG);
    if (r == pid_) {
      reaped_ = true;
      return WIFEXITED(status_) ? WEXITSTATUS(status_) : 128 + WTERMSIG(status_);
    }
    if (mt::SteadyClock::now() >= deadline) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, &status_, 0);
      reaped_ = true;
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

// ---------------------------------------------------------------------------------------------------------- helpers
std::uint16_t freePort() {
  const int fd = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(a);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) < 0 ||
      ::getsockname(fd, reinterpret_cast<sockaddr*>(&a), &len) < 0) {
    throw std::runtime_error("no free port");
  }
  ::close(fd);
  return ntohs(a.sin_port);
}

std::string ownNodeUri() {
  std::string uri, error;
  if (!mt::lookupNode(ros::this_node::getName(), mt::after(5.0), &uri, &error)) throw std::runtime_error(error);
  return uri;
}

bool waitFor(const std::function<bool()>& done, double timeout) {
  const auto deadline = mt::after(timeout);
  while (!done()) {
    if (mt::SteadyClock::now() >= deadline) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

// ---------------------------------------------------------------------------------------------------------- RawPeer
RawPeer::RawPeer(const std::string& service, Script script) : service_(service), script_(std::move(script)) {
  listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t len = sizeof(a);
  if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&a), sizeof(a)) < 0 || ::listen(listen_fd_, 16) < 0 ||
      ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&a), &len) < 0 || ::pipe2(wake_, O_CLOEXEC) < 0) {
    throw std::runtime_error("raw peer: cannot listen");
  }
  port_ = ntohs(a.sin_port);
  uri_ = mt::rosrpcUri("127.0.0.1", port_);
  thread_ = std::thread([this] { loop(); });
  XmlRpc::XmlRpcValue params, unused;
  params[0] = ros::this_node::getName();
  params[1] = service_;
  params[2] = uri_;
  params[3] = ownNodeUri();
  std::string error;
  if (!mt::callMaster("registerService", params, &unused, mt::after(5.0), &error)) {
    throw std::runtime_error("raw peer: " + error);
  }
}

RawPeer::~RawPeer() {
  XmlRpc::XmlRpcValue params, unused;
  params[0] = ros::this_node::getName();
  params[1] = service_;
  params[2] = uri_;
  std::string error;
  mt::callMaster("unregisterService", params, &unused, mt::after(5.0), &error);
  const char b = 0;
  (void)!::write(wake_[1], &b, 1);
  thread_.join();
  ::close(listen_fd_);
  ::close(wake_[0]);
  ::close(wake_[1]);
}

void RawPeer::loop() {
  for (;;) {
    pollfd fds[2] = {{listen_fd_, POLLIN, 0}, {wake_[0], POLLIN, 0}};
    if (::poll(fds, 2, -1) < 0 && errno != EINTR) return;
    if (fds[1].revents) return;
    if (!fds[0].revents) continue;
    const int fd = ::accept4(listen_fd_, nullptr, nullptr, SOCK_CLOEXEC);
    if (fd < 0) continue;
    ++connections;
    script_(fd);
    ::close(fd);
    ++closed;
  }
}

bool RawPeer::readHeader(int fd, mt::HeaderFields* fields) {
  std::uint8_t len[4];
  if (!recvAll(fd, len, 4)) return false;
  std::vector<std::uint8_t> body(mt::readLength(len));
  std::string error;
  return recvAll(fd, body.data(), body.size()) && mt::decodeHeader(body.data(), body.size(), fields, &error);
}

bool RawPeer::writeRaw(int fd, const std::vector<std::uint8_t>& bytes) {
  return ::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(bytes.size());
}

bool RawPeer::writeHeader(int fd, const mt::HeaderFields& fields) {
  const std::vector<std::uint8_t> body = mt::encodeHeader(fields);
  std::vector<std::uint8_t> out(4);
  const std::uint32_t n = static_cast<std::uint32_t>(body.size());
  std::memcpy(out.data(), &n, 4);
  out.insert(out.end(), body.begin(), body.end());
  return writeRaw(fd, out);
}

bool RawPeer::readRequest(int fd, std::vector<std::uint8_t>* payload) {
  std::uint8_t len[4];
  if (!recvAll(fd, len, 4)) return false;
  payload->resize(mt::readLength(len));
  if (!recvAll(fd, payload->data(), payload->size())) return false;
  ++requests;
  return true;
}

bool RawPeer::writeAnswer(int fd, bool ok, const std::vector<std::uint8_t>& payload) {
  std::vector<std::uint8_t> out(5);
  out[0] = ok ? 1 : 0;
  const std::uint32_t n = static_cast<std::uint32_t>(payload.size());
  std::memcpy(out.data() + 1, &n, 4);
  out.insert(out.end(), payload.begin(), payload.end());
  return writeRaw(fd, out);
}

mt::HeaderFields RawPeer::serverHeader(const std::string& md5sum) {
  return {{"callerid", "/raw_peer"},
          {"md5sum", md5sum},
          {"type", "moverl_msgs/ExecuteTrajectory"},
          {"request_type", "moverl_msgs/ExecuteTrajectoryRequest"},
          {"response_type", "moverl_msgs/ExecuteTrajectoryResponse"}};
}

void RawPeer::resetClose(int fd) {
  linger l{1, 0};
  setsockopt(fd, SOL_SOCKET, SO_LINGER, &l, sizeof(l));
}

bool RawPeer::sendsMore(int fd, double timeout) {
  pollfd p{fd, POLLIN, 0};
  if (::poll(&p, 1, static_cast<int>(timeout * 1000)) <= 0) return false;
  std::uint8_t b;
  return ::recv(fd, &b, 1, MSG_PEEK | MSG_DONTWAIT) > 0;
}

}  // namespace moverl_tcpros_test
