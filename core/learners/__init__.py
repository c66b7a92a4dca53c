"""The rival learners: tabular Q(lambda), and the deep baselines on a Gymnasium env.

The environment (`srlab/AmigoTrack-v0`) is the same world and stimuli as srlab's.
"""
