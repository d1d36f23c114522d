"""The shipping rule of the measured-data page (``benchmarks/real_validation.py``) and every decision taken under
it: the rule's text and, per decision, its date, task, candidate, what was compared and the outcome. The page
renders them as they stand here; a new decision is a new row.
"""

RULE = ("A network, or a change to how networks are trained, ships only if on the measured-data validation set "
        "(split real, honest captures) its task's primary metric is no worse than the shipped network's by more "
        "than the run-to-run spread of that metric over training seeds; the spread is measured over at least three "
        "seeds of the same training and recorded here with the decision.")
# each decision: (date, task, candidate, what was compared, outcome)
DECISIONS = (
    ("2026-11-27", "all", "the shipped networks (trained before the measured set existed)",
     "first score on the measured set: the baseline each later candidate is compared with", "kept (baseline)"),
    ("2026-12-02", "depth", "the shipped networks, on the measured depth set grown from the Motorcycle to nine "
     "Middlebury 2014 scenes", "re-scored on the new set, beside two more seeds of the same training for the spread: "
     "the baseline later depth candidates are compared with", "kept (baseline)"),
    ("2026-12-02", "hdr", "the proposed network with a shorter highlight solve, for a 512² reconstruction within 1 s: "
     "20 + 20 iterations in 4 restarts, and 24 + 24 in 6 (shipped: 40 + 40 in 8), each trained 500 steps at this "
     "code (benchmarks/hdr_fewer_iters.py)", "highlight PSNR on the measured set 43.45 and 43.47 dB against the "
     "shipped 44.01 dB (spread 0.23 dB); 0.58× and 0.63× the shipped network's reconstruction time",
     "not shipped: worse by more than the spread"),
    ("2026-12-02", "hdr", "the proposed network retrained as shipped (40 + 40 in 8, 500 steps, seed 0) at this code: "
     "the control for the shorter solves", "highlight PSNR on the measured set 43.78 dB against 44.01 dB (−0.24 dB, "
     "the spread 0.23 dB; the shipped network's other seeds read 44.26 and 43.79 dB)",
     "not shipped: no better, and worse by just more than the spread"),
    ("2026-12-02", "hyperspectral", "the proposed network retrained as shipped (200 steps, seed 0) at this code: "
     "`doefab train --task hyperspectral --variant proposed --steps 200 --minutes 600`, scored as this script "
     "scores a network (evaluate_split)", "PSNR on the measured set 6.905 dB against the shipped 6.903 dB (spread "
     "0.0033 dB); SAM 0.535 rad for both; 10.86 dB on validation for both",
     "not shipped: within the spread, so the rule allows it, but no gain, and a new network re-opens the published "
     "tables"),
    ("2026-12-02", "depth", "the proposed network retrained as shipped (500 steps, seed 0) at this code: `doefab "
     "train --task depth --variant proposed --steps 500 --minutes 600`, scored as this script scores a network",
     "MAE on the measured set 0.272 m against the shipped 0.285 m (spread 0.023 m), δ<1.25 0.869 against 0.856; on "
     "validation 0.251 against 0.258 m, δ<1.25 0.912 against 0.897", "not shipped: better in MAE and δ<1.25 on both "
     "sets, but by less than the seed moves it, and a new network re-opens Table 3 and the half-ring's tolerance "
     "pages"),
    ("2026-12-07", "depth", "the proposed network trained as shipped but for 1000 steps instead of 500 (its validation "
     "curve levels off from step 700), and the same with half the training scenes drawn as rooms and streets "
     "(slanted and curved surfaces, objects evenly in inverse depth); benchmarks/depth_recipes.py",
     "MAE on the measured set 0.268 and 0.253 m against the shipped 0.285 m (spread 0.023 m), δ<1.25 0.882 and 0.895 "
     "against 0.856; on validation 0.212 and 0.237 m against 0.258 m; a wall at 1 m behind the validation "
     "photographs read at 1.13 and 1.10 m against 2.03 m", "1000 steps shipped with its two ablations trained alike "
     "(1000 steps each): no worse on the measured set (better, by less than the spread), better on validation by "
     "0.046 m, and it reads near walls the shipped network misplaced by a metre; the room layouts not shipped: within "
     "the spread of it on the measured set, worse on validation, their curve still falling"),
    ("2026-12-07", "depth", "two more seeds of the shipped recipe (1000 steps, seeds 1 and 2: `doefab train --task "
     "depth --variant proposed --steps 1000 --minutes 600 --seed S`, one torch thread each, two at a time, at 9000440)",
     "MAE on the measured set 0.293 and 0.262 m beside the shipped network's 0.268 m: the recipe's spread 0.016 m "
     "(the 500-step recipe's 0.023 m); δ<1.25 0.858 and 0.874 beside 0.882", "kept: the decisions above stand at "
     "this spread (the 1000-step network is better than the 500-step one, the rule asks it no worse; the room "
     "layouts' 0.253 m lies within 0.016 m of it); later depth candidates are read against 0.016 m"),
    ("2026-12-08", "hdr", "the proposed network trained as shipped but for 1000 steps instead of 500, at 41de3a1 (its "
     "validation PSNR, 54.35 dB at step 500 of the shipped run, reads 54.44 at step 500 and 54.86 at step 1000); "
     "benchmarks/training_plateau.py", "highlight PSNR on the measured set 43.99 dB against the shipped 44.01 dB "
     "(spread 0.23 dB, the 500-step recipe's; the 1000-step recipe's not measured); on validation 26.37 against "
     "26.40 dB", "shipped with its two ablations trained alike (1000 steps each, not chosen by the rule: coded only "
     "reads 39.20 against 39.82 dB on the measured set, 24.47 against 23.63 dB on validation): no worse on the "
     "measured set within the spread, and trained at the current code and scene generators, which the shipped "
     "networks' records do not name"),
    ("2026-12-08", "hyperspectral", "the proposed network trained as shipped but for 600 steps instead of 200, at "
     "41de3a1 (its validation PSNR stays within 6.93–6.99 dB from step 50 on); benchmarks/training_plateau.py",
     "PSNR on the measured set 6.897 dB against the shipped 6.903 dB (spread 0.0033 dB); SAM 0.5351 against "
     "0.5348 rad; on validation 10.86 dB for both", "not shipped: worse by more than the spread; the curve says "
     "200 steps already reach the plateau"),
    ("2026-12-08", "hyperspectral", "the proposed network retrained as shipped (200 steps, seed 0) at 41de3a1, the "
     "current code and scene generators; benchmarks/training_plateau.py", "PSNR on the measured set 6.905 dB against "
     "the shipped 6.903 dB (spread 0.0033 dB); SAM 0.5348 rad for both; on validation 10.86 dB for both",
     "shipped with its two ablations trained alike (200 steps each): no worse on the measured set, and trained at "
     "the current code and scene generators (the decision of 2026-12-02 kept the older network for want of a gain; "
     "the rule asks for none)"),
)
