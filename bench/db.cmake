# Store ingest: samples/s into a file; CPU share of 16 cells x 250 Hz.
arena_bench(db_bench SOURCES ${CMAKE_CURRENT_LIST_DIR}/db_bench.cpp LIBS arena::db)
