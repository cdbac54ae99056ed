# The Debian package (`cpack -G DEB` in the build folder): the three programs, the plot tool,
# the demo and the documents. raystack-plot needs python3-matplotlib, recommended rather than
# required (it is large, and the renderer does not need it).
# Library dependencies are read off the binaries by dpkg-shlibdeps; mpirun itself comes from
# openmpi-bin, which no binary links, so it is named here.
set(CPACK_PACKAGE_NAME raystack)
set(CPACK_PACKAGE_VENDOR "raystack")
set(CPACK_PACKAGE_CONTACT "raystack developers <raystack@localhost>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY
    "Distributed out-of-core ray tracer for triangle models larger than one machine's RAM")
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION graphics)
set(CPACK_DEBIAN_PACKAGE_SHLIBDEPS ON)
set(CPACK_DEBIAN_PACKAGE_DEPENDS "openmpi-bin")
set(CPACK_DEBIAN_PACKAGE_RECOMMENDS "python3-matplotlib")
set(CPACK_GENERATOR DEB)
include(CPack)
