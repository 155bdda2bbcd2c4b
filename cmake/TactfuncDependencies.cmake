# Every dependency comes from Debian 12's packages (see scripts/install_deps.sh).
find_package(Eigen3 3.3 REQUIRED NO_MODULE)
find_package(Ceres 2.1 REQUIRED)
include(TactfuncSharedCeres)
# flann's own config (brings lz4); pkg-config flann would drag HDF5 and MPI flags in.
find_package(flann CONFIG REQUIRED)
find_package(OpenCV 4 REQUIRED COMPONENTS core imgproc imgcodecs videoio)
find_package(Boost 1.71 REQUIRED)
find_package(Threads REQUIRED)
find_package(PNG REQUIRED)  # the dataset PNG writer (estimation/data/internal/png_writer.h)
# libdeflate: the PNG reader's inflate for the common frames (estimation/data/internal/png_reader.cc).
find_package(PkgConfig REQUIRED)
pkg_check_modules(LIBDEFLATE REQUIRED IMPORTED_TARGET libdeflate)
find_package(nlohmann_json 3 REQUIRED)  # dataset.json (estimation, private)
if(TACTFUNC_BUILD_APPS)
  find_package(benchmark REQUIRED)
  find_package(CLI11 CONFIG REQUIRED)
  # Optional: with MPI, `mpirun -np N tactfunc train|encode|recon|eval|bench posterior`
  # runs as N processes (docs/SCALING.md); without it the program runs alone and refuses
  # mpirun.
  if(TACTFUNC_MPI)
    set(MPI_CXX_SKIP_MPICXX ON)  # the C API only, not the deprecated C++ bindings
    find_package(MPI COMPONENTS CXX)
  endif()
  if(MPI_CXX_FOUND)
    message(STATUS "tactfunc: MPI ${MPI_CXX_VERSION} found: train, encode, recon, eval and bench posterior run under mpirun")
  else()
    message(STATUS "tactfunc: building without MPI (every command runs as one process)")
  endif()
endif()
