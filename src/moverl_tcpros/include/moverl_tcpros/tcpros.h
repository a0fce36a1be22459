// moverl_tcpros: ROS services over TCPROS, served and called by the thread that needs them, every wait with a deadline,
// every request sent at most once (README.md).
#pragma once

#include "moverl_tcpros/call_end.h"
#include "moverl_tcpros/client.h"
#include "moverl_tcpros/master.h"
#include "moverl_tcpros/server.h"
#include "moverl_tcpros/socket.h"
