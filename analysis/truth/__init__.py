"""The gap benchmark's truth simulator: trials made by a richer simulation than the diagnosis's
own model (:mod:`ramdaq.analysis.gap` never imports it), with one hidden effect built physically."""
