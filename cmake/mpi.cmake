# The MPI layer (src/mpi, docs/MPI.md): `mpirun -n N vnr train|decode|eval|render` over the bricks of a
# multi-brick model. On by default when an MPI C library is found (Debian: libopenmpi-dev, openmpi-bin);
# without it those commands run in one process as before.
find_package(MPI QUIET COMPONENTS C)
option(VNR_MPI "Build the MPI layer: distributed training, decoding, evaluation and rendering of bricks" ${MPI_C_FOUND})
if(VNR_MPI)
  if(NOT MPI_C_FOUND)
    message(FATAL_ERROR "VNR_MPI is ON but no MPI library was found (Debian: libopenmpi-dev openmpi-bin)")
  endif()
  file(GLOB vnr_mpi_srcs CONFIGURE_DEPENDS ${CMAKE_CURRENT_SOURCE_DIR}/src/mpi/*.cpp)
  add_library(vnr_mpi STATIC ${vnr_mpi_srcs})
  target_include_directories(vnr_mpi PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/src)
  target_compile_options(vnr_mpi PRIVATE ${VNR_WARNINGS})
  target_link_libraries(vnr_mpi PUBLIC vnr MPI::MPI_C)
  # The C API from C++: no deprecated MPI-2 C++ bindings (they need libmpi_cxx).
  target_compile_definitions(vnr_mpi PUBLIC OMPI_SKIP_MPICXX=1 MPICH_SKIP_MPICXX=1)
  target_link_libraries(vnr_cli PRIVATE vnr_mpi)
  target_compile_definitions(vnr_cli PRIVATE VNR_HAVE_MPI=1)
  if(VNR_BUILD_TESTS)
    # Tests under mpirun: as root in containers Open MPI needs the two ALLOW_RUN_AS_ROOT variables. They
    # compare ranks and one process bit for bit on the CPU: no GPU even where one is visible.
    find_program(VNR_MPIEXEC NAMES mpirun mpiexec HINTS ${MPIEXEC_EXECUTABLE})
    set(vnr_mpi_env OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
                    OMP_NUM_THREADS=1 CUDA_VISIBLE_DEVICES= VNR_CLI=$<TARGET_FILE:vnr_cli>)
    add_executable(test_mpi_units tests/mpi/test_mpi_units.cpp)
    target_link_libraries(test_mpi_units PRIVATE vnr_mpi GTest::gtest GTest::gtest_main)
    gtest_discover_tests(test_mpi_units DISCOVERY_TIMEOUT 60 PROPERTIES TIMEOUT 300 LABELS cpu)
    add_executable(mpi_collectives tests/mpi/mpi_collectives.cpp)
    target_link_libraries(mpi_collectives PRIVATE vnr_mpi)
    target_compile_options(mpi_collectives PRIVATE ${VNR_WARNINGS})
    foreach(n 2 4)
      add_test(NAME mpi_collectives_n${n} COMMAND ${VNR_MPIEXEC} -n ${n} --oversubscribe $<TARGET_FILE:mpi_collectives>
                                                  ${CMAKE_CURRENT_BINARY_DIR}/mpi_collectives_n${n})
      set_tests_properties(mpi_collectives_n${n} PROPERTIES ENVIRONMENT "${vnr_mpi_env}" LABELS cpu TIMEOUT 120)
      add_test(NAME mpi_cli_n${n} COMMAND bash ${CMAKE_CURRENT_SOURCE_DIR}/tests/mpi/cli_mpi.sh ${n}
                                          ${CMAKE_CURRENT_BINARY_DIR}/mpi_cli_n${n})
      set_tests_properties(mpi_cli_n${n} PROPERTIES ENVIRONMENT "${vnr_mpi_env}" LABELS cpu TIMEOUT 300)
    endforeach()
  endif()
endif()
