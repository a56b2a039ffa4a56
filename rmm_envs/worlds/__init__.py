"""What the worlds of several systems share: input bounds (:mod:`.bounds`) and compiled one-path
failure tests (:mod:`.path_kernels`).  Each system's own world (circles, mazes, rooms, maps) is in
its folder, ``rmm_envs/systems/<system>/``."""
