# Every third-party library Rime uses, found once here. README.md says why each is needed.
find_package(Eigen3 3.3 REQUIRED NO_MODULE)        # dense 3x3 algebra in host-only code (tests, libs/clean)
find_package(TBB REQUIRED)                         # CPU backend of the execution layer
find_package(HDF5 REQUIRED COMPONENTS C)           # particle frames (H5Part layout)
find_package(tomlplusplus REQUIRED)                # scene files with source positions for errors
find_package(CLI11 REQUIRED)                       # command lines of every tool
find_package(assimp REQUIRED)                      # mesh import for boundary sampling
find_package(nlohmann_json REQUIRED)              # JSON summaries, stats logs and reports
find_package(Threads REQUIRED)
find_package(fmt REQUIRED)                         # string formatting (g++ 12 has no <format>)

# OpenVDB's CMake module ships in the Debian package's multiarch lib folder.
if(NOT OpenVDB_FOUND)
  foreach(dir /usr/lib/x86_64-linux-gnu/cmake/OpenVDB /usr/lib/aarch64-linux-gnu/cmake/OpenVDB /usr/local/lib/cmake/OpenVDB)
    if(EXISTS ${dir})
      list(APPEND CMAKE_MODULE_PATH ${dir})
    endif()
  endforeach()
endif()
find_package(OpenVDB QUIET)                        # level sets for surface reconstruction
find_package(CGAL QUIET)                           # mesh repair, remeshing, decimation

if(RIME_BUILD_TESTS)
  find_package(GTest REQUIRED)
endif()
