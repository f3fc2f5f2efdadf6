# Helpers shared by every facescan target: warnings (ours only, never global) and test registration.
include_guard(GLOBAL)

function(facescan_warnings target)
    # C++ only: idlc-generated C sources compile inside the wire library and are not ours to warn about.
    target_compile_options(${target} PRIVATE $<$<COMPILE_LANGUAGE:CXX>:-Wall -Wextra -Wpedantic -Wnon-virtual-dtor>)
    if(CMAKE_CXX_COMPILER_ID STREQUAL "GNU")
        # GCC 12 reports maybe-uninitialized inside OpenMesh's and Eigen's templates at -O2 (false positives in
        # code we do not own, e.g. OpenMesh::PropertyT<Vec3uc>::push_back); -Wuninitialized stays on.
        target_compile_options(${target} PRIVATE
            $<$<COMPILE_LANGUAGE:CXX>:-Wshadow=local -Wno-maybe-uninitialized>)
        # GCC 12 at -O3 (Release) reports a false -Wrestrict inside libstdc++'s operator+(const char*, string&&),
        # i.e. for every `"x" + std::string(...)` that it happens to inline (GCC bug 105651, fixed in GCC 13). In
        # files built with a precompiled header it inlines more of them, and the same false report comes as
        # -Wstringop-overflow, -Wstringop-overread or -Warray-bounds on char_traits::copy.
        # Off for that compiler and configuration only: the -O2 builds (RelWithDebInfo) and clang's keep them, and
        # the fuzzers run under AddressSanitizer.
        if(CMAKE_CXX_COMPILER_VERSION VERSION_GREATER_EQUAL 12 AND CMAKE_CXX_COMPILER_VERSION VERSION_LESS 13)
            target_compile_options(${target} PRIVATE $<$<AND:$<COMPILE_LANGUAGE:CXX>,$<CONFIG:Release>>:
                -Wno-restrict -Wno-stringop-overflow -Wno-stringop-overread -Wno-array-bounds>)
        endif()
    else()
        target_compile_options(${target} PRIVATE $<$<COMPILE_LANGUAGE:CXX>:-Wshadow-uncaptured-local>)
    endif()
    if(FACESCAN_WERROR)
        target_compile_options(${target} PRIVATE $<$<COMPILE_LANGUAGE:CXX>:-Werror>)
    endif()
endfunction()

# facescan_test_flags(target): how a test's own code is compiled. The test programs and the precompiled header
# they share (tests/CMakeLists.txt) both take them from here: GCC refuses a precompiled header built with other
# flags, and CMake's -Winvalid-pch with our -Werror makes that a build error.
function(facescan_test_flags target)
    target_link_libraries(${target} PRIVATE facescan_test_common GTest::gtest)
    target_compile_definitions(${target} PRIVATE
        FACESCAN_SOURCE_DIR="${PROJECT_SOURCE_DIR}"
        FACESCAN_BINARY_DIR="${PROJECT_BINARY_DIR}")
    facescan_warnings(${target})
    # The test's own code at -Og in Release: what it tests (the libraries and programs) keeps the users' -O3, and
    # the test files (gtest macros, many small lambdas) compile about a third faster at -O1 than at -O3 and a sixth
    # faster again at -Og (failover_test, finishing_test and server_test: 24.3 s at -O1, 20.2 s at -Og), which
    # keeps the CI suite near its time on 2 cores. Benchmarks are not built through here and keep -O3.
    target_compile_options(${target} PRIVATE $<$<CONFIG:Release>:-Og>)
endfunction()

# facescan_add_test(NAME name SOURCES a.cpp ... LIBS lib ... [LABELS l ...] [TIMEOUT s] [COST s] [RUN_SERIAL])
# One gtest executable, discovered test by test so ctest reports each case.
# COST: about the seconds its slower cases take. ctest starts costlier tests first, but it learns their times only
# from an earlier run in the same tree, and CI's tree is always fresh: there it started them in file order, and a
# 45 s failover case that came last ran on alone at the end of the suite.
function(facescan_add_test)
    cmake_parse_arguments(T "RUN_SERIAL" "NAME;TIMEOUT;COST" "SOURCES;LIBS;LABELS" ${ARGN})
    add_executable(${T_NAME} ${T_SOURCES})
    target_link_libraries(${T_NAME} PRIVATE ${T_LIBS} GTest::gtest_main)
    facescan_test_flags(${T_NAME})
    if(TARGET facescan_test_pch)
        target_precompile_headers(${T_NAME} REUSE_FROM facescan_test_pch)
    endif()
    if(NOT T_TIMEOUT)
        set(T_TIMEOUT 300)
    endif()
    include(GoogleTest)
    # Built up one pair at a time: an empty LABELS value would vanish from the flattened list and shift every
    # later pair (tests without labels got the label RUN_SERIAL, and RUN_SERIAL tests ran in parallel).
    set(props TIMEOUT ${T_TIMEOUT})
    if(T_LABELS)
        list(APPEND props LABELS "${T_LABELS}")
    endif()
    if(T_COST)
        list(APPEND props COST ${T_COST})
    endif()
    if(T_RUN_SERIAL)
        list(APPEND props RUN_SERIAL TRUE)
    endif()
    gtest_discover_tests(${T_NAME} DISCOVERY_TIMEOUT 60 PROPERTIES ${props})
endfunction()

# facescan_precompile(target <header> ...): precompiles the standard headers every facescan library uses and the
# given third-party ones (Eigen, OpenCV, Cyclone DDS) once for the target. They took 1.5-3.5 s to parse in each
# source file: most of the compile time of a file, and of CI's build on 2 cores. C++ only: the C sources that idlc
# generates compile as before. Sources still include what they use; a precompiled header only makes it faster.
function(facescan_precompile target)
    set(headers <algorithm> <chrono> <cmath> <cstdint> <filesystem> <functional> <map> <memory> <mutex> <optional>
        <string> <thread> <vector> ${ARGN})
    set(cxx_only "")
    foreach(h IN LISTS headers)
        string(REPLACE ">" "$<ANGLE-R>" h "${h}")
        list(APPEND cxx_only "$<$<COMPILE_LANGUAGE:CXX>:${h}>")
    endforeach()
    target_precompile_headers(${target} PRIVATE ${cxx_only})
endfunction()
