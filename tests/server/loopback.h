// Loopback ports for the real servers tests start (nginx, redis-server).
#pragma once

#include <sys/types.h>

namespace motionlod::server::testing {

// A loopback port free now (the kernel's choice for a socket bound to port 0).
int FreePort();
// Whether something accepts TCP connections on 127.0.0.1:`port`.
bool Accepts(int port);
// Waits up to 10 s for the child process `pid` (just started) to accept on `port`: false
// when it did not, with `pid` set to -1 when it exited meanwhile.
bool WaitUntilAccepting(pid_t& pid, int port);

}  // namespace motionlod::server::testing
