# Cross-compiled Linux controller: pass-through wrappers for the two socket options qemu-user
# does not translate (see sockopt_compat.c: on a real kernel they change nothing).
target_sources(arm_controller PRIVATE "${CMAKE_CURRENT_LIST_DIR}/sockopt_compat.c")
target_link_options(arm_controller PRIVATE "-Wl,--wrap=setsockopt,--wrap=getsockopt")
