# Simulators (issue 13): MuJoCo's convergence at its default settings and its
# cost per simulated second against arena's model on the same campaign scenes.
arena_bench(mujoco_study SOURCES ${CMAKE_CURRENT_LIST_DIR}/mujoco_study.cpp
            LIBS arena::simulators arena::orchestrator)
