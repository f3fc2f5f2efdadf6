# The Debian package (CPack's DEB generator): one package, facescan, for the compute box and the capture PC alike.
#   cmake -S . -B build-deb -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX=/usr
#   cmake --build build-deb && (cd build-deb && cpack)          -> build-deb/facescan_<version>_<arch>.deb
# Dependencies come from dpkg-shlibdeps (the shared libraries the programs link) plus the data package of the
# Haar cascade and adduser; /etc/facescan/*.conf are conffiles; postinst creates the system user facescan.
# A Debian package installs under /usr only: a tree configured with another prefix refuses to make one.
include_guard(GLOBAL)

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME facescan)
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_VENDOR facescan)
set(CPACK_PACKAGE_CONTACT "facescan maintainers <facescan@localhost>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "real-time 3D face scanning with a consumer depth camera")
set(CPACK_PACKAGE_DESCRIPTION
    "A person turns their head in front of a Kinect-class depth camera; facescan fuses the depth stream into an\n"
    "accurate coloured face mesh in real time and serves it over the network (Cyclone DDS). facescan-agent runs\n"
    "beside the camera, facescan-server on the compute box (systemd unit facescan-server.service), and the\n"
    "facescan client watches scans and fetches meshes. facescan-bench measures speed and accuracy.")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_STRIP_FILES ON)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_PACKAGE_PRIORITY optional)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
# Not shared libraries, so dpkg-shlibdeps cannot see them: the Haar cascade the server's detector loads
# (FACESCAN_HAAR_FRONTAL), the tool postinst falls back on to create the system user, and the openssl program
# facescan-site (deploy/security/site.sh) makes a site's keys and certificates with.
set(CPACK_DEBIAN_PACKAGE_DEPENDS "opencv-data, adduser, openssl")
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "systemd")
set(CPACK_DEBIAN_PACKAGE_HOMEPAGE "https://facescan.invalid/")

# Maintainer scripts and the conffiles list (absolute paths of this install).
set(pkg_dir ${PROJECT_BINARY_DIR}/package)
foreach(script postinst prerm postrm)
    configure_file(${PROJECT_SOURCE_DIR}/deploy/debian/${script}.in ${pkg_dir}/${script} @ONLY)
endforeach()
file(WRITE ${pkg_dir}/conffiles "${FACESCAN_INSTALL_FULL_CONFDIR}/server.conf\n${FACESCAN_INSTALL_FULL_CONFDIR}/agent.conf\n")
set(CPACK_DEBIAN_PACKAGE_CONTROL_EXTRA ${pkg_dir}/postinst ${pkg_dir}/prerm ${pkg_dir}/postrm ${pkg_dir}/conffiles)
set(CPACK_DEBIAN_PACKAGE_CONTROL_STRICT_PERMISSION TRUE)

# Checked when cpack runs (the prefix is fixed at configure time, in units and compiled-in paths).
set(FACESCAN_PACKAGE_PREFIX ${CMAKE_INSTALL_PREFIX})
configure_file(${PROJECT_SOURCE_DIR}/deploy/debian/cpack_project_config.cmake.in
               ${pkg_dir}/cpack_project_config.cmake @ONLY)
set(CPACK_PROJECT_CONFIG_FILE ${pkg_dir}/cpack_project_config.cmake)
include(CPack)
