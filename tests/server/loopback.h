// Loopback ports for the real servers tests start (nginx, redis-server).
#pragma once

namespace motionlod::server::testing {

// A loopback port free now (the kernel's choice for a socket bound to port 0).
int FreePort();
// Whether something accepts TCP connections on 127.0.0.1:`port`.
bool Accepts(int port);

}  // namespace motionlod::server::testing
