# `cmake --install`: the binary, the static libraries and their public headers, a CMake
# package (find_package(tetstream) with imported targets tetstream::tetstream (the
# public API), tetstream::core, ::io and ::pipeline), a pkg-config file, the man page
# (generated from --help at build time), bash and zsh completions; and CPack's Debian
# package (`cpack -G DEB`).
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

# tetstream_pipeline is an interface target over the pipeline's rooms (pipeline/CMakeLists.txt),
# each a static library of its own, installed and exported beside it.
set(TETSTREAM_PIPELINE_LIBRARIES "")
foreach(room ${TETSTREAM_PIPELINE_ROOMS})
  list(APPEND TETSTREAM_PIPELINE_LIBRARIES tetstream_pipeline_${room})
endforeach()
set(TETSTREAM_LIBRARIES tetstream_core tetstream_io tetstream_pipeline ${TETSTREAM_PIPELINE_LIBRARIES})
set(TETSTREAM_PACKAGE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/tetstream)
# The libraries include headers from the source root ("io/tet_reader.hpp"); installed,
# from include/tetstream.
foreach(lib core io pipeline)
  set_target_properties(tetstream_${lib} PROPERTIES EXPORT_NAME ${lib} INTERFACE_INCLUDE_DIRECTORIES
    "$<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}>;$<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}/tetstream>")
  file(GLOB_RECURSE headers RELATIVE ${PROJECT_SOURCE_DIR} CONFIGURE_DEPENDS ${PROJECT_SOURCE_DIR}/${lib}/*.hpp)
  list(REMOVE_ITEM headers io/hdf5_detail.hpp)  # needs hdf5.h; only for io's own sources
  foreach(header ${headers})
    get_filename_component(dir ${header} DIRECTORY)
    install(FILES ${header} DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/tetstream/${dir} COMPONENT dev)
  endforeach()
endforeach()
foreach(room ${TETSTREAM_PIPELINE_ROOMS})
  set_target_properties(tetstream_pipeline_${room} PROPERTIES EXPORT_NAME pipeline_${room} INTERFACE_INCLUDE_DIRECTORIES
    "$<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}>;$<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}/tetstream>")
endforeach()
# pkg-config lists the rooms from the top down, so that a room's symbols follow their users.
set(TETSTREAM_PC_PIPELINE "")
foreach(room ${TETSTREAM_PIPELINE_ROOMS})
  string(PREPEND TETSTREAM_PC_PIPELINE "-ltetstream_pipeline_${room} ")
endforeach()

# The public API (api/, docs/cpp.md): tetstream::tetstream, #include <tetstream/tetstream.hpp>.
set_target_properties(tetstream_api PROPERTIES EXPORT_NAME tetstream INTERFACE_INCLUDE_DIRECTORIES
  "$<BUILD_INTERFACE:${PROJECT_SOURCE_DIR}/api>;$<INSTALL_INTERFACE:${CMAKE_INSTALL_INCLUDEDIR}>")
install(FILES ${PROJECT_SOURCE_DIR}/api/tetstream/tetstream.hpp DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/tetstream
        COMPONENT dev)
list(APPEND TETSTREAM_LIBRARIES tetstream_api)

install(TARGETS tetstream RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR} COMPONENT bin)
install(TARGETS ${TETSTREAM_LIBRARIES} EXPORT tetstreamTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR} COMPONENT dev)
install(EXPORT tetstreamTargets NAMESPACE tetstream:: DESTINATION ${TETSTREAM_PACKAGE_DIR} COMPONENT dev)

configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/tetstreamConfig.cmake.in
                              ${PROJECT_BINARY_DIR}/tetstreamConfig.cmake INSTALL_DESTINATION ${TETSTREAM_PACKAGE_DIR})
write_basic_package_version_file(${PROJECT_BINARY_DIR}/tetstreamConfigVersion.cmake COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/tetstreamConfig.cmake ${PROJECT_BINARY_DIR}/tetstreamConfigVersion.cmake
        DESTINATION ${TETSTREAM_PACKAGE_DIR} COMPONENT dev)

# pkg-config: the same libraries, for builds without CMake.
# Relocatable: the prefix is found from the .pc file's own place (pkg-config's pcfiledir).
file(RELATIVE_PATH TETSTREAM_PC_TO_PREFIX "/${CMAKE_INSTALL_LIBDIR}/pkgconfig" "/")
string(REGEX REPLACE "/$" "" TETSTREAM_PC_TO_PREFIX "${TETSTREAM_PC_TO_PREFIX}")
set(TETSTREAM_PC_HDF5 "")
if(TETSTREAM_HDF5_BUILT)
  list(JOIN TETSTREAM_HDF5_LIBRARIES " " TETSTREAM_PC_HDF5)
endif()
configure_file(${PROJECT_SOURCE_DIR}/cmake/tetstream.pc.in ${PROJECT_BINARY_DIR}/tetstream.pc @ONLY)
install(FILES ${PROJECT_BINARY_DIR}/tetstream.pc DESTINATION ${CMAKE_INSTALL_LIBDIR}/pkgconfig COMPONENT dev)

# The man page, from the built binary's help (cmake/man_page.cmake).
option(TETSTREAM_MAN "Generate the man page tetstream(1) from --help at build time" ON)
if(TETSTREAM_MAN)
  add_custom_command(OUTPUT ${PROJECT_BINARY_DIR}/tetstream.1
                     # A sanitized binary would fail `--help` on LeakSanitizer's report of
                     # objects still held at exit: leaks do not matter to the page.
                     COMMAND ${CMAKE_COMMAND} -E env ASAN_OPTIONS=detect_leaks=0
                             ${CMAKE_COMMAND} -DTETSTREAM=$<TARGET_FILE:tetstream> -DVERSION=${PROJECT_VERSION}
                             -DOUT=${PROJECT_BINARY_DIR}/tetstream.1 -P ${PROJECT_SOURCE_DIR}/cmake/man_page.cmake
                     DEPENDS tetstream ${PROJECT_SOURCE_DIR}/cmake/man_page.cmake
                     COMMENT "Generating the man page tetstream.1 from --help" VERBATIM)
  add_custom_target(tetstream_man ALL DEPENDS ${PROJECT_BINARY_DIR}/tetstream.1)
  install(FILES ${PROJECT_BINARY_DIR}/tetstream.1 DESTINATION ${CMAKE_INSTALL_MANDIR}/man1 COMPONENT bin)
endif()

install(FILES ${PROJECT_SOURCE_DIR}/completions/tetstream.bash RENAME tetstream
        DESTINATION ${CMAKE_INSTALL_DATADIR}/bash-completion/completions COMPONENT bin)
install(FILES ${PROJECT_SOURCE_DIR}/completions/_tetstream
        DESTINATION ${CMAKE_INSTALL_DATADIR}/zsh/vendor-completions COMPONENT bin)
install(FILES ${PROJECT_SOURCE_DIR}/README.md DESTINATION ${CMAKE_INSTALL_DOCDIR} COMPONENT bin)
install(DIRECTORY ${PROJECT_SOURCE_DIR}/docs/ DESTINATION ${CMAKE_INSTALL_DOCDIR} COMPONENT bin
        FILES_MATCHING PATTERN "*.md")

# CPack: one Debian package with everything (cpack -G DEB in the build directory).
set(CPACK_PACKAGE_NAME tetstream)
set(CPACK_PACKAGE_VENDOR "tetstream")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY "Exact out-of-core 3D Delaunay triangulation")
set(CPACK_PACKAGE_VERSION ${PROJECT_VERSION})
set(CPACK_PACKAGE_CONTACT "tetstream maintainers <tetstream@localhost>")
set(CPACK_GENERATOR DEB)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
# The binary's shared libraries from dpkg-shlibdeps (dpkg-dev) where it is installed,
# else named here (Debian 12's); the development packages the headers and the CMake
# package need are recommended.
find_program(TETSTREAM_DPKG_SHLIBDEPS dpkg-shlibdeps)
if(TETSTREAM_DPKG_SHLIBDEPS)
  set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
else()
  set(CPACK_DEBIAN_PACKAGE_DEPENDS
      "libboost-iostreams1.74.0, libzstd1, zlib1g, libspdlog1.10-fmt9 | libspdlog1.10, libfmt9, libgomp1, libstdc++6")
  if(TETSTREAM_HDF5_BUILT)
    string(APPEND CPACK_DEBIAN_PACKAGE_DEPENDS ", libhdf5-103-1")
  endif()
endif()
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS
    "libboost-iostreams-dev, libzstd-dev, zlib1g-dev, libspdlog-dev, nlohmann-json3-dev, pkg-config")
if(TETSTREAM_HDF5_BUILT)
  string(APPEND CPACK_DEBIAN_PACKAGE_RECOMMENDS ", libhdf5-dev")
endif()
include(CPack)
