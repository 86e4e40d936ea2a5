// Names of gRPC status codes as the service's documentation, logs and clients' reports write them.
#pragma once

#include <grpcpp/support/status_code_enum.h>

namespace evloc::wire {

// The name of a gRPC status code as docs/api.md writes it (e.g. "RESOURCE_EXHAUSTED"); "other"
// for a code the API never returns.
const char* StatusCodeName(grpc::StatusCode code);

}  // namespace evloc::wire
