# Speed/accuracy study (issue 7): convergence of the model against the closed
# forms of the mechanics validation tests (bench/README.md, "Convergence").
arena_bench(convergence_study SOURCES ${CMAKE_CURRENT_LIST_DIR}/convergence_study.cpp LIBS arena::mechanics)
target_include_directories(convergence_study PRIVATE ${PROJECT_SOURCE_DIR}/tests/mechanics)
# Residuals and solve success per case of the mechanics extremes suite ("Extremes").
arena_bench(extremes_table SOURCES ${CMAKE_CURRENT_LIST_DIR}/extremes_table.cpp LIBS arena::mechanics)
target_include_directories(extremes_table PRIVATE ${PROJECT_SOURCE_DIR}/tests/mechanics)

# LCP solver comparison (section "LCP solvers"): optional, built only when the
# peers' Debian packages are present (benchmark-only, never a runtime
# dependency): scripts/setup.sh --bench-peers (libsiconos-numerics-dev,
# libbullet-dev, libdart-dev)
find_path(ARENA_SICONOS_INCLUDE siconos/numerics/LCP_Solvers.h)
find_library(ARENA_SICONOS_NUMERICS siconos_numerics)
find_path(ARENA_BULLET_INCLUDE BulletDynamics/MLCPSolvers/btLemkeAlgorithm.h PATH_SUFFIXES bullet)
find_library(ARENA_BULLET_DYNAMICS BulletDynamics-float64)
find_library(ARENA_BULLET_LINEARMATH LinearMath-float64)
if(ARENA_SICONOS_INCLUDE AND ARENA_SICONOS_NUMERICS AND ARENA_BULLET_INCLUDE AND ARENA_BULLET_DYNAMICS
   AND ARENA_BULLET_LINEARMATH)
  arena_bench(lcp_solvers_bench SOURCES ${CMAKE_CURRENT_LIST_DIR}/lcp_solvers_bench.cpp
              LIBS arena::mechanics ${ARENA_SICONOS_NUMERICS} ${ARENA_BULLET_DYNAMICS} ${ARENA_BULLET_LINEARMATH})
  target_include_directories(lcp_solvers_bench PRIVATE ${PROJECT_SOURCE_DIR}/tests/mechanics
                             ${ARENA_SICONOS_INCLUDE} ${ARENA_SICONOS_INCLUDE}/siconos
                             ${ARENA_SICONOS_INCLUDE}/siconos/numerics ${ARENA_BULLET_INCLUDE})
  target_compile_definitions(lcp_solvers_bench PRIVATE BT_USE_DOUBLE_PRECISION)
  # DART's Lemke is a further optional peer (libdart-dev): without it the
  # program still builds and prints the other solvers' rows.
  find_path(ARENA_DART_INCLUDE dart/lcpsolver/Lemke.hpp)
  find_library(ARENA_DART_LIBRARY dart)
  if(ARENA_DART_INCLUDE AND ARENA_DART_LIBRARY)
    target_include_directories(lcp_solvers_bench PRIVATE ${ARENA_DART_INCLUDE})
    target_link_libraries(lcp_solvers_bench PRIVATE ${ARENA_DART_LIBRARY})
    target_compile_definitions(lcp_solvers_bench PRIVATE ARENA_HAVE_DART)
  else()
    message(STATUS "lcp_solvers_bench: DART's Lemke left out (needs libdart-dev; benchmark only)")
  endif()
else()
  message(STATUS "lcp_solvers_bench skipped: needs libsiconos-numerics-dev and libbullet-dev (benchmark only)")
endif()
