// What nearly every test file includes and takes longest to parse: precompiled once for all test programs
// (tests/CMakeLists.txt). Tests still include what they use; this only makes it faster.
#pragma once

#include <gtest/gtest.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <chrono>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <opencv2/core.hpp>
#include <string>
#include <thread>
#include <vector>
