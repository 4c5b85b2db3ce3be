# Scene/campaign reading and trial planning (scene engineer).
arena_bench(campaign_bench SOURCES ${CMAKE_CURRENT_LIST_DIR}/campaign_bench.cpp
            LIBS arena::orchestrator arena::mechanics)
