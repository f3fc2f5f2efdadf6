// Status and StatusOr: how facescan reports failure at I/O boundaries (files, network bytes, devices).
// Expected outcomes inside the pipeline (tracking lost, no face) are values of their own, not Status.
#pragma once

#include <optional>
#include <string>
#include <utility>
#include <variant>

namespace facescan {

enum class StatusCode {
    kOk = 0,
    kInvalidArgument,   // the caller's input is wrong (sizes, ranges, flags)
    kDataLoss,          // bytes are corrupt or truncated
    kOutOfRange,        // a count or size exceeds what we accept
    kNotFound,          // a file, device, session or peer does not exist
    kUnavailable,       // a peer or device is not reachable now; trying later may work
    kDeadlineExceeded,  // no answer in time
    kAlreadyExists,
    kResourceExhausted,  // out of a limited resource (sessions, buffers)
    kInternal,
    kUnimplemented,
    kPermissionDenied,  // credentials do not allow it: DDS Security access control, a bad identity file
};

const char* statusCodeName(StatusCode code);

class [[nodiscard]] Status {
 public:
    Status() = default;
    Status(StatusCode code, std::string message) : code_(code), message_(std::move(message)) {}

    static Status ok() { return {}; }
    bool isOk() const { return code_ == StatusCode::kOk; }
    explicit operator bool() const { return isOk(); }
    StatusCode code() const { return code_; }
    const std::string& message() const { return message_; }
    // "DATA_LOSS: depth payload truncated (12 of 600 bytes)"
    std::string toString() const;

 private:
    StatusCode code_ = StatusCode::kOk;
    std::string message_;
};

inline Status invalidArgument(std::string m) { return {StatusCode::kInvalidArgument, std::move(m)}; }
inline Status dataLoss(std::string m) { return {StatusCode::kDataLoss, std::move(m)}; }
inline Status outOfRange(std::string m) { return {StatusCode::kOutOfRange, std::move(m)}; }
inline Status notFound(std::string m) { return {StatusCode::kNotFound, std::move(m)}; }
inline Status unavailable(std::string m) { return {StatusCode::kUnavailable, std::move(m)}; }
inline Status deadlineExceeded(std::string m) { return {StatusCode::kDeadlineExceeded, std::move(m)}; }
inline Status resourceExhausted(std::string m) { return {StatusCode::kResourceExhausted, std::move(m)}; }
inline Status internalError(std::string m) { return {StatusCode::kInternal, std::move(m)}; }
inline Status permissionDenied(std::string m) { return {StatusCode::kPermissionDenied, std::move(m)}; }

template <typename T>
class [[nodiscard]] StatusOr {
 public:
    StatusOr(T value) : value_(std::move(value)) {}         // NOLINT(google-explicit-constructor)
    StatusOr(Status status) : status_(std::move(status)) {  // NOLINT(google-explicit-constructor)
        if (status_.isOk()) status_ = internalError("StatusOr constructed from an OK status without a value");
    }
    bool isOk() const { return value_.has_value(); }
    explicit operator bool() const { return isOk(); }
    const Status& status() const { return status_; }
    T& value() & { return *value_; }
    const T& value() const& { return *value_; }
    T&& value() && { return std::move(*value_); }
    T* operator->() { return &*value_; }
    const T* operator->() const { return &*value_; }
    T& operator*() & { return *value_; }
    const T& operator*() const& { return *value_; }

 private:
    Status status_;
    std::optional<T> value_;
};

}  // namespace facescan

#define FACESCAN_CONCAT_INNER(a, b) a##b
#define FACESCAN_CONCAT(a, b) FACESCAN_CONCAT_INNER(a, b)

// Returns from the enclosing function when `expr` (a Status) is not OK.
#define RETURN_IF_ERROR(expr)                                  \
    do {                                                       \
        ::facescan::Status facescan_status_ = (expr);          \
        if (!facescan_status_.isOk()) return facescan_status_; \
    } while (0)

// ASSIGN_OR_RETURN(auto x, makeX()); returns the error status of a failed StatusOr.
#define ASSIGN_OR_RETURN(lhs, expr) ASSIGN_OR_RETURN_IMPL(FACESCAN_CONCAT(facescan_so_, __LINE__), lhs, expr)
#define ASSIGN_OR_RETURN_IMPL(tmp, lhs, expr) \
    auto tmp = (expr);                        \
    if (!tmp.isOk()) return tmp.status();     \
    lhs = std::move(tmp).value()
