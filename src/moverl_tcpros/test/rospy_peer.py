#!/usr/bin/env python3
"""A real rospy peer for test_tcpros: a server or a client of moverl_msgs/ExecuteTrajectory (run with /usr/bin/python3).

    rospy_peer.py server <service>
        Serve <service>; each answer's message is "rospy <n>" (n counts the requests served) and its state.position is
        [request.not_after]. A request with not_after < 0 fails (the handler raises). Prints "ready" once registered,
        serves until stdin closes, then prints "served <n>".
    rospy_peer.py client <service> <calls> <persistent 0|1> [reset]
        Make <calls> calls with not_after = 0.5, 1.5, ... (with [reset]: of type moverl_msgs/ResetRobot instead, whose
        md5sum differs). Prints "answer <message> <state.position[0]>" or "error <why>" per call.

The master is $ROS_MASTER_URI; the node's name is anonymous.
"""

import sys
import threading

import rospy

from moverl_msgs.srv import ExecuteTrajectory, ExecuteTrajectoryResponse, ResetRobot


def serve(service: str) -> None:
    """Serve until stdin closes."""
    served = [0]

    def handle(req):
        if req.not_after < 0:
            raise RuntimeError("asked to fail")
        served[0] += 1
        res = ExecuteTrajectoryResponse()
        res.message = f"rospy {served[0]}"
        res.state.position = [req.not_after]
        return res

    rospy.init_node("rospy_peer_server", anonymous=True, disable_signals=True)
    rospy.Service(service, ExecuteTrajectory, handle)
    print("ready", flush=True)
    done = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    done.wait()
    rospy.signal_shutdown("stdin closed")
    print(f"served {served[0]}", flush=True)


def call(service: str, calls: int, persistent: bool, reset: bool) -> None:
    """Make the calls and print what each gave."""
    rospy.init_node("rospy_peer_client", anonymous=True, disable_signals=True)
    proxy = rospy.ServiceProxy(service, ResetRobot if reset else ExecuteTrajectory, persistent=persistent)
    for i in range(calls):
        try:
            res = proxy(not_after=i + 0.5) if not reset else proxy(positions=[0.0], not_after=i + 0.5)
            print(f"answer {res.message} {res.state.position[0] if res.state.position else 'none'}", flush=True)
        except (rospy.ServiceException, rospy.ROSException) as e:
            print(f"error {' '.join(str(e).split())}", flush=True)
    proxy.close()


def main() -> int:
    """Entry point."""
    args = sys.argv[1:]
    if len(args) == 2 and args[0] == "server":
        serve(args[1])
        return 0
    if len(args) in (4, 5) and args[0] == "client" and args[3] in ("0", "1") and args[4:] in ([], ["reset"]):
        call(args[1], int(args[2]), args[3] == "1", args[4:] == ["reset"])
        return 0
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main())
