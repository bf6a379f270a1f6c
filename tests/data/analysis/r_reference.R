# R's fits of ratings_r_reference.csv, frozen as r_reference.json for tests/analysis/test_ordinal.py and
# tests/analysis/test_stats.py (CI never needs R). Run from the repository root:
#   Rscript tests/data/analysis/r_reference.R
# The same rater exclusion as the report (any catch rating >= 3 removes every rating of that rater), then
# test rows only.
suppressPackageStartupMessages({library(ordinal); library(lmerTest); library(jsonlite)})
here <- "tests/data/analysis"
d <- read.csv(file.path(here, "ratings_r_reference.csv"), stringsAsFactors = FALSE)
bad <- unique(d$rater_id[d$role == "catch" & d$rating >= 3])
d <- d[!(d$rater_id %in% bad) & d$role == "test", ]
# NAT is the reference level, as in the report
d$condition <- relevel(factor(d$condition), ref = "NAT")
d$rater_id <- factor(d$rater_id)
d$clip_id <- factor(d$clip_id)

t0 <- proc.time()[["elapsed"]]
o <- clmm(factor(rating, ordered = TRUE) ~ condition + (1 | rater_id) + (1 | clip_id), data = d)
clmm_seconds <- proc.time()[["elapsed"]] - t0
so <- summary(o)
co <- coef(so)
vc <- VarCorr(o)

m <- lmerTest::lmer(rating ~ condition + (1 | rater_id) + (1 | clip_id), data = d)
sm <- summary(m, ddf = "Satterthwaite")
cm <- coef(sm)
vm <- as.data.frame(VarCorr(m))
kr <- summary(m, ddf = "Kenward-Roger")
ckr <- coef(kr)

nm <- function(x) setNames(as.list(unname(x)), names(x))
fe_name <- function(x) {  # the report's names: Intercept, condition[T.MG]
  x <- sub("^\\(Intercept\\)$", "Intercept", x)
  sub("^condition(.*)$", "condition[T.\\1]", x)
}
fix <- function(v) setNames(as.list(unname(v)), fe_name(names(v)))
ranef_sd <- function(g) attr(vc[[g]], "stddev")[[1]]

out <- list(
  versions = list(R = R.version.string, ordinal = as.character(packageVersion("ordinal")),
                  lme4 = as.character(packageVersion("lme4")), lmerTest = as.character(packageVersion("lmerTest"))),
  data = list(n = nrow(d), n_raters = nlevels(d$rater_id), n_clips = nlevels(d$clip_id),
              excluded_raters = sort(bad)),
  clmm = list(
    call = "clmm(factor(rating, ordered=TRUE) ~ condition + (1|rater_id) + (1|clip_id), data=d)",
    thresholds = nm(o$alpha), fixed_effects = fix(o$beta),
    std_errors = fix(co[names(o$beta), "Std. Error"]),
    threshold_std_errors = nm(co[names(o$alpha), "Std. Error"]),
    sd_rater = ranef_sd("rater_id"), sd_clip = ranef_sd("clip_id"),
    log_likelihood = as.numeric(logLik(o)), max_abs_gradient = max(abs(o$gradient)),
    seconds = clmm_seconds),
  lmer = list(
    call = "lmerTest::lmer(rating ~ condition + (1|rater_id) + (1|clip_id), data=d); summary(ddf='Satterthwaite')",
    fixed_effects = fix(cm[, "Estimate"]), std_errors = fix(cm[, "Std. Error"]), df = fix(cm[, "df"]),
    t = fix(cm[, "t value"]), p_values = fix(cm[, "Pr(>|t|)"]),
    df_kenward_roger = fix(ckr[, "df"]), p_values_kenward_roger = fix(ckr[, "Pr(>|t|)"]),
    variance_components = list(rater = vm$vcov[vm$grp == "rater_id"], clip = vm$vcov[vm$grp == "clip_id"],
                               residual = vm$vcov[vm$grp == "Residual"]),
    reml_log_likelihood = as.numeric(logLik(m)))
)
writeLines(toJSON(out, auto_unbox = TRUE, digits = NA, pretty = TRUE), file.path(here, "r_reference.json"))
print(so)
print(sm)
