/* LD_PRELOAD shim: a socket bound (or made to listen) on the wildcard address is bound to loopback instead.
 *
 * roscpp's XML-RPC server (xmlrpcpp) always binds INADDR_ANY, and with ROS_HOSTNAME=127.0.0.1 so do its
 * TCPROS and UDPROS servers: without this shim every roscpp node of a MoveRL graph (rosout, planning_scene_node,
 * shield_node) is reachable from the network. With it, in every process that loads it:
 *   bind(0.0.0.0:port) -> bind(127.0.0.1:port), bind([::]:port) -> bind([::1]:port);
 *   listen() on a socket never bound (which the kernel would bind to the wildcard) binds it to loopback first.
 * Any other address (an explicit interface address, 127.0.0.1 itself, a Unix socket) is left untouched, so a
 * program that asks for a specific interface still gets it. Not covered: a UDP socket that sends before any
 * bind() is bound by the kernel to 0.0.0.0 (connected ones, e.g. DNS queries, accept only their peer);
 * src/moverl_gym/test/test_graph_lifecycle.py lists every socket a graph listens on.
 *
 * Cost: one comparison per bind()/listen() call, which a ROS node makes a handful of times at start-up; nothing
 * on the send/receive path.
 */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <errno.h>
#include <netinet/in.h>
#include <string.h>
#include <sys/socket.h>

typedef int (*bind_fn)(int, const struct sockaddr *, socklen_t);
typedef int (*listen_fn)(int, int);

static bind_fn real_bind;
static listen_fn real_listen;

__attribute__((constructor)) static void moverl_loopback_init(void) {
  real_bind = (bind_fn)dlsym(RTLD_NEXT, "bind");
  real_listen = (listen_fn)dlsym(RTLD_NEXT, "listen");
}

int bind(int fd, const struct sockaddr *addr, socklen_t len) {
  if (!real_bind) moverl_loopback_init();
  if (addr && addr->sa_family == AF_INET && len >= (socklen_t)sizeof(struct sockaddr_in)) {
    struct sockaddr_in in;
    memcpy(&in, addr, sizeof in);
    if (in.sin_addr.s_addr == htonl(INADDR_ANY)) {
      in.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
      return real_bind(fd, (const struct sockaddr *)&in, sizeof in);
    }
  } else if (addr && addr->sa_family == AF_INET6 && len >= (socklen_t)sizeof(struct sockaddr_in6)) {
    struct sockaddr_in6 in6;
    memcpy(&in6, addr, sizeof in6);
    if (IN6_IS_ADDR_UNSPECIFIED(&in6.sin6_addr)) {
      in6.sin6_addr = in6addr_loopback;
      return real_bind(fd, (const struct sockaddr *)&in6, sizeof in6);
    }
  }
  return real_bind(fd, addr, len);
}

int listen(int fd, int backlog) {
  if (!real_listen) moverl_loopback_init();
  struct sockaddr_storage ss;
  socklen_t len = sizeof ss;
  int saved = errno;
  if (getsockname(fd, (struct sockaddr *)&ss, &len) == 0) {
    /* Never bound: port 0 on the wildcard address. Bind it to loopback (bind() above does the rewrite). */
    if (ss.ss_family == AF_INET && ((struct sockaddr_in *)&ss)->sin_port == 0) {
      bind(fd, (struct sockaddr *)&ss, sizeof(struct sockaddr_in));
    } else if (ss.ss_family == AF_INET6 && ((struct sockaddr_in6 *)&ss)->sin6_port == 0) {
      bind(fd, (struct sockaddr *)&ss, sizeof(struct sockaddr_in6));
    }
  }
  errno = saved;
  return real_listen(fd, backlog);
}
