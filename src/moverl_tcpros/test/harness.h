// What test_tcpros runs its peers with: child processes (a ROS master of its own, rospy peers, the roscpp helper),
// a raw TCPROS peer whose every byte the test decides, and a per-test deadline.
#pragma once

#include <sys/types.h>

#include <atomic>
#include <cstdint>
#include <functional>
#include <string>
#include <thread>
#include <vector>

#include "moverl_tcpros/socket.h"

namespace moverl_tcpros_test {

/// \brief A child process with its stdin and stdout piped to us (stderr inherited). It is killed (SIGKILL) when this
///        object goes, and by the kernel when the test binary dies (PR_SET_PDEATHSIG).
class Child {
 public:
  explicit Child(const std::vector<std::string>& argv);
  ~Child();
  Child(const Child&) = delete;
  Child& operator=(const Child&) = delete;
  pid_t pid() const { return pid_; }
  /// \brief The next line of its stdout within `timeout` s; false at its end or the timeout.
  bool readLine(std::string* line, double timeout);
  /// \brief Close its stdin (peers stop on that).
  void closeStdin();
  void writeLine(const std::string& line);
  /// \brief Send `sig`.
  void signal(int sig);
  /// \brief Wait up to `timeout` s for it to exit: its exit status, or -1 (then it is killed).
  int wait(double timeout);

 private:
  pid_t pid_ = -1;
  int in_ = -1, out_ = -1;
  std::string buffer_;
  bool reaped_ = false;
  int status_ = 0;
};

/// \brief A port nobody listens on right now (on 127.0.0.1).
std::uint16_t freePort();

/// \brief Our XML-RPC URI, as the master has it.
std::string ownNodeUri();

/// \brief A TCPROS peer on raw sockets, registered with the master as `service`: for each connection (one at a time)
///        it runs `script(fd)` in a thread of its own, then closes the connection (unless the script did). Counts the
///        connections and the complete requests it read (readRequest).
class RawPeer {
 public:
  using Script = std::function<void(int fd)>;
  RawPeer(const std::string& service, Script script);
  ~RawPeer();
  RawPeer(const RawPeer&) = delete;
  RawPeer& operator=(const RawPeer&) = delete;
  std::uint16_t port() const { return port_; }

  std::atomic<int> connections{0};  ///< connections accepted
  std::atomic<int> requests{0};     ///< complete requests read
  std::atomic<int> closed{0};       ///< connections the peer has closed

  // For scripts (blocking, each with a 5 s bound).
  static bool readHeader(int fd, moverl_tcpros::HeaderFields* fields);
  static bool writeRaw(int fd, const std::vector<std::uint8_t>& bytes);
  static bool writeHeader(int fd, const moverl_tcpros::HeaderFields& fields);
  /// \brief Read one request (counted in `requests` when complete).
  bool readRequest(int fd, std::vector<std::uint8_t>* payload);
  /// \brief [ok][length][payload].
  static bool writeAnswer(int fd, bool ok, const std::vector<std::uint8_t>& payload);
  /// \brief A header a TCPROS server of ExecuteTrajectory sends (md5sum as given).
  static moverl_tcpros::HeaderFields serverHeader(const std::string& md5sum);
  /// \brief Make the close that follows reset the connection (SO_LINGER 0) instead of ending it (FIN).
  static void resetClose(int fd);
  /// \brief Whether the client sends anything more within `timeout` s (false at its close).
  static bool sendsMore(int fd, double timeout);

 private:
  void loop();
  std::string service_, uri_;
  Script script_;
  int listen_fd_ = -1, wake_[2] = {-1, -1};
  std::uint16_t port_ = 0;
  std::thread thread_;
};

/// \brief Wait (polling every 10 ms) up to `timeout` s for `done()`.
bool waitFor(const std::function<bool()>& done, double timeout);

}  // namespace moverl_tcpros_test
