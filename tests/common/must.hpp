// The value of a test's set-up step that cannot fail in a working build (a participant, a topic, a reader): the
// test stops at once when it does, with the status as the failure message.
#pragma once

#include <gtest/gtest.h>

#include <cstdlib>
#include <utility>

#include "recon/status.hpp"

namespace facescan::testing {

template <typename T>
T must(StatusOr<T> made) {
    if (!made.isOk()) {
        ADD_FAILURE() << made.status().toString();
        std::abort();
    }
    return std::move(made).value();
}

}  // namespace facescan::testing
