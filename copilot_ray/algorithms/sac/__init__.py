"""Goal-conditioned SAC on whole tasks (`algorithm: sac`) and the same with hindsight relabelling
(`algorithm: her`): the paper's SAC and HER baselines."""
