# Where facescan installs (FHS through GNUInstallDirs) and the one pattern for data files.
#
# Installed layout (prefix /usr for the .deb, /usr/local for a plain `cmake --install`):
#   <prefix>/bin/facescan-server, facescan-agent, facescan, facescan-bench
#   <prefix>/share/facescan/<SUB>/...      data files: profiles/ (DDS XML), and what later features add
#   <prefix>/share/doc/facescan/           README
#   <confdir>/server.conf, agent.conf      configuration; <confdir> = /etc/facescan for prefix /usr, else
#                                          <prefix>/etc/facescan
#   <unitdir>/facescan-server.service ...  systemd units; /lib/systemd/system for prefix /usr, else
#                                          <prefix>/lib/systemd/system (systemd looks in /usr/local/lib/systemd too)
#   <prefix>/lib/sysusers.d, lib/sysctl.d  the system user and the socket-buffer limit the lan profile needs
#
# Programs find data files at run time with wire/data_files.hpp (findShareFile("profiles/lan.xml")): next to the
# running program (<exe>/../share/facescan, so an installed tree works wherever it is unpacked), then the build
# tree's mirror, then the configured install location. facescan_install_data() feeds both places:
#   facescan_install_data(DIRECTORY <dir> DESTINATION <SUB>)   # the folder's contents -> share/facescan/<SUB>
#   facescan_install_data(FILES <file>... DESTINATION <SUB>)
# Relative paths are relative to the calling CMakeLists.txt. In the build tree <build>/share/facescan/<SUB> is
# a link to the sources, so editing a data file needs no rebuild.
include_guard(GLOBAL)

set(FACESCAN_SHARE_SUBDIR ${CMAKE_INSTALL_DATADIR}/facescan)
set(FACESCAN_BUILD_SHARE_DIR ${PROJECT_BINARY_DIR}/share/facescan)
set(FACESCAN_INSTALL_FULL_SHARE_DIR ${CMAKE_INSTALL_FULL_DATADIR}/facescan)
if(CMAKE_INSTALL_PREFIX STREQUAL "/usr")
    # Debian's places for a system package (GNUInstallDirs maps only the FULL sysconfdir to /etc).
    set(FACESCAN_INSTALL_CONFDIR /etc/facescan)
    set(FACESCAN_INSTALL_UNITDIR /lib/systemd/system)
else()
    set(FACESCAN_INSTALL_CONFDIR ${CMAKE_INSTALL_SYSCONFDIR}/facescan)
    set(FACESCAN_INSTALL_UNITDIR lib/systemd/system)
endif()
# Absolute forms, for what is written into units and help texts.
foreach(var CONFDIR UNITDIR)
    if(IS_ABSOLUTE "${FACESCAN_INSTALL_${var}}")
        set(FACESCAN_INSTALL_FULL_${var} ${FACESCAN_INSTALL_${var}})
    else()
        set(FACESCAN_INSTALL_FULL_${var} ${CMAKE_INSTALL_PREFIX}/${FACESCAN_INSTALL_${var}})
    endif()
endforeach()

function(facescan_install_data)
    cmake_parse_arguments(D "" "DIRECTORY;DESTINATION" "FILES" ${ARGN})
    if(NOT D_DESTINATION OR (NOT D_DIRECTORY AND NOT D_FILES))
        message(FATAL_ERROR "facescan_install_data(DIRECTORY dir | FILES f... DESTINATION sub)")
    endif()
    set(mirror ${FACESCAN_BUILD_SHARE_DIR}/${D_DESTINATION})
    if(D_DIRECTORY)
        get_filename_component(src ${D_DIRECTORY} ABSOLUTE)
        install(DIRECTORY ${src}/ DESTINATION ${FACESCAN_SHARE_SUBDIR}/${D_DESTINATION})
        get_filename_component(parent ${mirror} DIRECTORY)
        file(MAKE_DIRECTORY ${parent})
        file(CREATE_LINK ${src} ${mirror} SYMBOLIC)
    endif()
    foreach(f IN LISTS D_FILES)
        get_filename_component(src ${f} ABSOLUTE)
        get_filename_component(name ${f} NAME)
        install(FILES ${src} DESTINATION ${FACESCAN_SHARE_SUBDIR}/${D_DESTINATION})
        file(MAKE_DIRECTORY ${mirror})
        file(CREATE_LINK ${src} ${mirror}/${name} SYMBOLIC)
    endforeach()
endfunction()

# facescan_install_programs(target...): into <prefix>/bin.
function(facescan_install_programs)
    install(TARGETS ${ARGN} RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
endfunction()
