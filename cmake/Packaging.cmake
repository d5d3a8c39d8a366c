# CPack: `cpack -G DEB` in the build folder makes procam_VERSION_ARCH.deb, installing under /usr:
# the procam binary, the static libraries, their headers and the CMake package. Its dependencies
# are the Debian packages procam builds against (their -dev packages bring the run-time
# libraries); a CUDA build also needs the CUDA toolkit, which is not a Debian package.
set(PROCAM_DEB_DEPENDS
  libeigen3-dev libceres-dev libembree-dev libopencv-dev nlohmann-json3-dev
  libspdlog-dev libfmt-dev libmrcal-dev libcgal-dev libzmq3-dev cppzmq-dev liblo-dev)
if(PROCAM_WITH_ARAVIS)
  list(APPEND PROCAM_DEB_DEPENDS libaravis-dev libusb-1.0-0-dev)
endif()
if(PROCAM_WITH_V4L2)
  list(APPEND PROCAM_DEB_DEPENDS libv4l-dev)
endif()
if(PROCAM_WITH_GLFW)
  list(APPEND PROCAM_DEB_DEPENDS libglfw3-dev libgl-dev libepoxy-dev libx11-dev libxrandr-dev)
endif()
if(PROCAM_PYTHON_MODULE)
  # `import procam` from /usr/lib/python3/dist-packages: the interpreter and NumPy it returns.
  list(APPEND PROCAM_DEB_DEPENDS python3 python3-numpy)
endif()
list(JOIN PROCAM_DEB_DEPENDS ", " CPACK_DEBIAN_PACKAGE_DEPENDS)

set(CPACK_GENERATOR DEB)
set(CPACK_PACKAGE_NAME procam)
set(CPACK_PACKAGE_VENDOR "the procam developers")
set(CPACK_PACKAGE_CONTACT "procam developers <procam@localhost>")
set(CPACK_PACKAGE_DESCRIPTION_SUMMARY
    "Projector-camera pipeline: calibration and interreflection compensation for projection rooms")
set(CPACK_PACKAGING_INSTALL_PREFIX /usr)
set(CPACK_DEBIAN_FILE_NAME DEB-DEFAULT)
set(CPACK_DEBIAN_PACKAGE_SECTION science)
set(CPACK_DEBIAN_COMPRESSION_TYPE gzip)  # xz takes minutes on the static libraries
include(CPack)
