"""InvertedPendulum under the target task (``InvertedPendulum``): Gymnasium's MuJoCo
``InvertedPendulum-v5`` (extra ``mujoco``).  Its spec: :mod:`.system`."""
