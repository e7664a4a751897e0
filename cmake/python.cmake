# The Python module `vnr` (src/python): on when pybind11 and Python 3's headers are found. Debian's
# /usr/bin/python3 is preferred over a python3 earlier on PATH (e.g. pyenv's, without numpy), so a plain
# configure builds for the Python that has python3-numpy. The module links the static layers, which are
# then compiled as position-independent code.
if(NOT DEFINED Python3_EXECUTABLE AND EXISTS /usr/bin/python3)
  set(Python3_EXECUTABLE /usr/bin/python3 CACHE FILEPATH "the Python 3 the vnr module is built for")
endif()
find_package(Python3 3.8 COMPONENTS Interpreter Development.Module QUIET)
if(Python3_FOUND)
  find_package(pybind11 2.6 CONFIG QUIET)
endif()
if(Python3_FOUND AND pybind11_FOUND)
  set(vnr_python_default ON)
else()
  set(vnr_python_default OFF)
endif()
option(VNR_PYTHON "Build the Python module vnr (pybind11, Python 3 headers)" ${vnr_python_default})
if(VNR_PYTHON)
  if(NOT Python3_FOUND OR NOT pybind11_FOUND)
    message(FATAL_ERROR "VNR_PYTHON needs Python 3's headers and pybind11: run scripts/setup.sh (python3-dev, "
                        "pybind11-dev) or configure with -DVNR_PYTHON=OFF")
  endif()
  set(CMAKE_POSITION_INDEPENDENT_CODE ON)
  # PIC lets GCC assume any global function may be interposed at load time, which stops it inlining
  # them; nothing interposes vnr's functions, so keep the inlining of a non-PIC build.
  add_compile_options($<$<COMPILE_LANGUAGE:CXX>:-fno-semantic-interposition>)
  # Where `cmake --install` puts the package, relative to the prefix: Debian's python3 looks in
  # <prefix>/lib/python3.X/dist-packages for /usr/local (and lib/python3/dist-packages for /usr).
  if(Python3_SITEARCH MATCHES "dist-packages")
    set(vnr_python_dir_default lib/python3.${Python3_VERSION_MINOR}/dist-packages)
  else()
    set(vnr_python_dir_default lib/python3.${Python3_VERSION_MINOR}/site-packages)
  endif()
  set(VNR_PYTHON_INSTALL_DIR ${vnr_python_dir_default} CACHE STRING
      "where the vnr Python package is installed (relative to CMAKE_INSTALL_PREFIX, or absolute)")
endif()
