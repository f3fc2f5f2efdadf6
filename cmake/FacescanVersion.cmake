# The version every program prints with --version: the project's version and the git commit it was built from.
# The commit is read when CMake configures; the files git moves on a commit or checkout are configure
# dependencies, so a build after a new commit re-runs CMake and rebuilds only version.cpp. Outside a git checkout
# (a source tarball) the commit reads "unknown".
#   target facescan_version: facescan/version.hpp (facescan::versionLine(program), printVersion(program))
include_guard(GLOBAL)

set(FACESCAN_GIT_COMMIT unknown)
find_package(Git QUIET)
if(GIT_FOUND)
    execute_process(COMMAND ${GIT_EXECUTABLE} rev-parse --short=12 HEAD WORKING_DIRECTORY ${PROJECT_SOURCE_DIR}
                    OUTPUT_VARIABLE commit OUTPUT_STRIP_TRAILING_WHITESPACE RESULT_VARIABLE git_rc ERROR_QUIET)
    if(git_rc EQUAL 0 AND commit)
        set(FACESCAN_GIT_COMMIT ${commit})
        # HEAD names a branch (or a commit); the branch's ref is a loose file or a line of packed-refs.
        execute_process(COMMAND ${GIT_EXECUTABLE} rev-parse --symbolic-full-name HEAD
                        WORKING_DIRECTORY ${PROJECT_SOURCE_DIR} OUTPUT_VARIABLE head_ref
                        OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
        set(git_files HEAD packed-refs)
        if(head_ref MATCHES "^refs/")
            list(APPEND git_files ${head_ref})
        endif()
        foreach(f IN LISTS git_files)
            execute_process(COMMAND ${GIT_EXECUTABLE} rev-parse --path-format=absolute --git-path ${f}
                            WORKING_DIRECTORY ${PROJECT_SOURCE_DIR} OUTPUT_VARIABLE path
                            OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
            if(path AND EXISTS ${path})
                set_property(DIRECTORY ${PROJECT_SOURCE_DIR} APPEND PROPERTY CMAKE_CONFIGURE_DEPENDS ${path})
            endif()
        endforeach()
    endif()
endif()

configure_file(${CMAKE_CURRENT_LIST_DIR}/version/version.cpp.in ${PROJECT_BINARY_DIR}/generated/version.cpp @ONLY)
add_library(facescan_version STATIC ${PROJECT_BINARY_DIR}/generated/version.cpp)
target_include_directories(facescan_version PUBLIC ${CMAKE_CURRENT_LIST_DIR}/version)
facescan_warnings(facescan_version)
