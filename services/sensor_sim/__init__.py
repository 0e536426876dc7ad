"""The world: draws the truth and every sensor's measurements (or replays recorded ones) and
publishes each operator's measurements on its own key, paced in real time or faster."""
