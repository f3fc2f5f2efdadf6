#include "recon/status.hpp"

namespace facescan {

const char* statusCodeName(StatusCode code) {
    switch (code) {
        case StatusCode::kOk: return "OK";
        case StatusCode::kInvalidArgument: return "INVALID_ARGUMENT";
        case StatusCode::kDataLoss: return "DATA_LOSS";
        case StatusCode::kOutOfRange: return "OUT_OF_RANGE";
        case StatusCode::kNotFound: return "NOT_FOUND";
        case StatusCode::kUnavailable: return "UNAVAILABLE";
        case StatusCode::kDeadlineExceeded: return "DEADLINE_EXCEEDED";
        case StatusCode::kAlreadyExists: return "ALREADY_EXISTS";
        case StatusCode::kResourceExhausted: return "RESOURCE_EXHAUSTED";
        case StatusCode::kInternal: return "INTERNAL";
        case StatusCode::kUnimplemented: return "UNIMPLEMENTED";
        case StatusCode::kPermissionDenied: return "PERMISSION_DENIED";
    }
    return "UNKNOWN";
}

std::string Status::toString() const {
    if (isOk()) return "OK";
    return std::string(statusCodeName(code_)) + ": " + message_;
}

}  // namespace facescan
