"""CartPole under the target task (``CartPole``): Gymnasium's ``CartPole-v1`` around a reckless
target-seeking LQR.  Its spec: :mod:`.system`."""
