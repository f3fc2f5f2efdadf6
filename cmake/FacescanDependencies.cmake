# Finds the six libraries of the design (all from Debian 12 packages). A missing one stops configure with the
# package to install; ./deploy/install-deps.sh installs them all.
include_guard(GLOBAL)

function(facescan_require found what package)
    if(NOT ${found})
        message(FATAL_ERROR "facescan: ${what} not found. Install it with: sudo apt-get install ${package}"
                            "  (or run ./deploy/install-deps.sh, which installs everything facescan needs)")
    endif()
endfunction()

find_package(OpenCV QUIET COMPONENTS core imgproc imgcodecs objdetect calib3d)
facescan_require(OpenCV_FOUND "OpenCV" "libopencv-dev")

find_package(Eigen3 QUIET NO_MODULE)
facescan_require(Eigen3_FOUND "Eigen3" "libeigen3-dev")

find_package(CycloneDDS QUIET)
facescan_require(CycloneDDS_FOUND "Cyclone DDS (C API and idlc)" "cyclonedds-dev cyclonedds-tools")

# DDS Security (deploy/security/): Cyclone's three built-in plugins, which Debian's libddsc0debian installs in a
# folder of its own, off the loader's path; the configuration names them by full path, so the folder is compiled
# in (FACESCAN_DDS_SECURITY_PLUGIN_DIR overrides it at run time). OpenSSL checks an identity's files at start-up.
get_target_property(_facescan_ddsc CycloneDDS::ddsc LOCATION)
get_filename_component(_facescan_ddsc_dir "${_facescan_ddsc}" DIRECTORY)
find_path(FACESCAN_DDS_SECURITY_PLUGIN_DIR libdds_security_auth.so
          HINTS ${_facescan_ddsc_dir}/libddsc0debian /usr/lib/${CMAKE_LIBRARY_ARCHITECTURE}/libddsc0debian
                ${_facescan_ddsc_dir} NO_DEFAULT_PATH)
facescan_require(FACESCAN_DDS_SECURITY_PLUGIN_DIR "Cyclone DDS Security plugins" "libddsc0debian")
find_package(OpenSSL QUIET)
facescan_require(OPENSSL_FOUND "OpenSSL" "libssl-dev")

find_package(draco QUIET)
facescan_require(draco_FOUND "Draco" "libdraco-dev")

# Debian's OpenMesh ships no version file, so no version may be asked for.
find_package(OpenMesh QUIET)
facescan_require(OpenMesh_FOUND "OpenMesh" "libopenmesh-dev")

find_package(PkgConfig QUIET)
facescan_require(PkgConfig_FOUND "pkg-config" "pkg-config")
# OpenNI2 has no CMake config in Debian; pkg-config names it libopenni2.
pkg_check_modules(OpenNI2 QUIET IMPORTED_TARGET libopenni2)
facescan_require(OpenNI2_FOUND "OpenNI2" "libopenni2-dev")

pkg_check_modules(Zstd QUIET IMPORTED_TARGET libzstd)
facescan_require(Zstd_FOUND "zstd" "libzstd-dev")
pkg_check_modules(TurboJpeg QUIET IMPORTED_TARGET libturbojpeg)
facescan_require(TurboJpeg_FOUND "libjpeg-turbo (TurboJPEG API)" "libturbojpeg0-dev")
# The same library's libjpeg API: the server decodes only the head's region of a colour frame, which TurboJPEG
# 2.1 cannot (its cropping region is 3.0's).
pkg_check_modules(Jpeg QUIET IMPORTED_TARGET libjpeg)
facescan_require(Jpeg_FOUND "libjpeg-turbo (libjpeg API)" "libjpeg62-turbo-dev")

# Recordings of today's depth cameras: Azure Kinect / Orbbec Femto .mkv files, demuxed by FFmpeg's libavformat.
pkg_check_modules(AvFormat QUIET IMPORTED_TARGET libavformat libavcodec libavutil)
facescan_require(AvFormat_FOUND "FFmpeg's libavformat" "libavformat-dev libavcodec-dev libavutil-dev")

# Intel RealSense .bag recordings: ROS 1 bags, read with ROS's rosbag storage library. Debian's rosbag_storage.pc
# requires pluginlib's, which Debian does not ship, so the headers and libraries are found directly.
find_path(ROSBAG_INCLUDE_DIR rosbag/bag.h)
find_path(SENSOR_MSGS_INCLUDE_DIR sensor_msgs/Image.h)
facescan_require(ROSBAG_INCLUDE_DIR "rosbag storage (ROS 1 bags)" "librosbag-storage-dev")
facescan_require(SENSOR_MSGS_INCLUDE_DIR "ROS sensor_msgs" "libsensor-msgs-dev libgeometry-msgs-dev libstd-msgs-dev")
# rosbag/bag.h includes pluginlib (for its encryption plugins), which includes class_loader and ROS 2's utilities;
# Debian installs each of these headers one folder down (/usr/include/NAME/NAME/...).
set(ROSBAG_EXTRA_INCLUDE_DIRS "")
foreach(name pluginlib class_loader ament_index_cpp rcpputils rcutils)
    if(EXISTS /usr/include/${name}/${name})
        list(APPEND ROSBAG_EXTRA_INCLUDE_DIRS /usr/include/${name})
    elseif(NOT EXISTS /usr/include/${name})
        facescan_require(FALSE "${name}'s headers (needed by rosbag storage)" "librosbag-storage-dev")
    endif()
endforeach()
if(NOT TARGET facescan::rosbag)
    add_library(facescan::rosbag INTERFACE IMPORTED)
    foreach(lib rosbag_storage roscpp_serialization rostime cpp_common console_bridge)
        find_library(ROSBAG_LIB_${lib} ${lib})
        facescan_require(ROSBAG_LIB_${lib} "lib${lib}" "librosbag-storage-dev")
        target_link_libraries(facescan::rosbag INTERFACE ${ROSBAG_LIB_${lib}})
    endforeach()
    target_include_directories(facescan::rosbag SYSTEM INTERFACE ${ROSBAG_INCLUDE_DIR} ${SENSOR_MSGS_INCLUDE_DIR}
                                                                   ${ROSBAG_EXTRA_INCLUDE_DIRS})
endif()

find_package(Threads REQUIRED)

# The client's GLB export (glTF 2.0 binary) and the web viewer's HTTP and WebSocket server.
find_package(TinyGLTF QUIET)
facescan_require(TinyGLTF_FOUND "TinyGLTF" "libtinygltf-dev")
# Not through civetweb's CMake config: Debian's (1.15+dfsg-4) also names the civetweb program, which is in another
# package (civetweb), and stops configure when that is absent. The header and the library are all we use.
find_package(ZLIB QUIET)  # the viewer gzips its page once at start
facescan_require(ZLIB_FOUND "zlib" "zlib1g-dev")
find_path(CIVETWEB_INCLUDE_DIR civetweb.h)
find_library(CIVETWEB_LIBRARY civetweb)
facescan_require(CIVETWEB_LIBRARY "CivetWeb (HTTP and WebSocket server)" "libcivetweb-dev")
facescan_require(CIVETWEB_INCLUDE_DIR "CivetWeb's header" "libcivetweb-dev")
if(NOT TARGET facescan::civetweb)
    add_library(facescan::civetweb UNKNOWN IMPORTED)
    set_target_properties(facescan::civetweb PROPERTIES IMPORTED_LOCATION "${CIVETWEB_LIBRARY}"
        INTERFACE_INCLUDE_DIRECTORIES "${CIVETWEB_INCLUDE_DIR}")
endif()

if(FACESCAN_BUILD_TESTS)
    find_package(GTest QUIET)
    facescan_require(GTest_FOUND "GoogleTest" "libgtest-dev")
endif()
if(FACESCAN_BUILD_BENCH)
    find_path(NANOFLANN_INCLUDE_DIR nanoflann.hpp)
    facescan_require(NANOFLANN_INCLUDE_DIR "nanoflann" "libnanoflann-dev")
endif()

# Haar cascades come from opencv-data; the path is compiled in as the default and can be overridden at run time.
find_file(FACESCAN_HAAR_FRONTAL haarcascade_frontalface_default.xml
          PATHS /usr/share/opencv4/haarcascades /usr/share/opencv/haarcascades NO_DEFAULT_PATH)
facescan_require(FACESCAN_HAAR_FRONTAL "OpenCV Haar cascades" "opencv-data")
