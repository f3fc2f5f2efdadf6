// Builds the test programs' shared precompiled header (tests/CMakeLists.txt, common/test_pch.hpp).
