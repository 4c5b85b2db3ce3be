# Orchestration overhead per trial and trials/hour end to end (issue 5): the
# real service in-process and real `arena cell` processes over DDS.
arena_bench(orchestration_bench SOURCES ${CMAKE_CURRENT_LIST_DIR}/orchestration_bench.cpp
            LIBS arena::orchestrator arena::db nlohmann_json::nlohmann_json spdlog::spdlog)
target_compile_definitions(orchestration_bench PRIVATE ARENA_BINARY="$<TARGET_FILE:arena>")
add_dependencies(orchestration_bench arena)
