//! Text- and skeleton-conditioned motion token generation (masked and autoregressive transformers), sampling, editing and the text-motion evaluator; built in the text-to-motion issue.
