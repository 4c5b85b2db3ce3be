# Simulators (issue 13): MuJoCo's convergence at its default settings and its
# cost per simulated second against arena's model on the same campaign scenes.
arena_bench(mujoco_study SOURCES ${CMAKE_CURRENT_LIST_DIR}/mujoco_study.cpp
            LIBS arena::simulators arena::orchestrator)
# The extremes table per simulator (issue 31): each swept row right against
# its closed form, or a typed error; exit 1 on a silent wrong answer.
arena_bench(truth_extremes SOURCES ${CMAKE_CURRENT_LIST_DIR}/truth_extremes.cpp
            LIBS arena::simulators arena::mechanics)
target_include_directories(truth_extremes PRIVATE ${PROJECT_SOURCE_DIR}/tests/mechanics)
