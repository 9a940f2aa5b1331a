//! The gRPC API (`proto/anymo.proto`, package `anymo.v1`), with server reflection, on the same
//! port as REST. Every call goes through the same operations, limits and keys as its REST twin.

use super::AppState;
use super::auth::{Access, ApiKeys};
use super::error::ApiError;
use super::generation::{self, Edit, Generated, SamplingOptions};
use super::motion::{ClipSource, SkeletonSource};
use super::search::{SearchParams, search};
use anymo_models::quality::QualityReport;
use anymo_models::tokens::TokenFile;
use std::sync::Arc;
use tonic::{Request, Response, Status};

/// The generated protocol types and service traits.
#[allow(missing_docs, clippy::all)]
pub mod proto {
    tonic::include_proto!("anymo.v1");
}

/// The descriptor set reflection serves.
pub const DESCRIPTOR_SET: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/anymo_descriptor.bin"));

use proto::anymo_server::{Anymo, AnymoServer};

/// The service.
pub struct AnymoService {
    state: Arc<AppState>,
}

/// The service as a tonic server, its messages bounded by the body limit.
pub fn service(state: Arc<AppState>) -> AnymoServer<AnymoService> {
    let limit = state.limits.body_bytes;
    AnymoServer::new(AnymoService { state }).max_decoding_message_size(limit).max_encoding_message_size(limit * 4)
}

fn key<T>(request: &Request<T>) -> Option<String> {
    ApiKeys::presented(&request.metadata().clone().into_headers()).map(str::to_string)
}

fn sampling(options: Option<proto::Sampling>) -> SamplingOptions {
    let o = options.unwrap_or_default();
    SamplingOptions {
        samples: o.samples.map(|s| s as usize),
        seed: o.seed,
        guidance: o.guidance,
        temperature: o.temperature,
        top_k: o.top_k.map(|k| k as usize),
        cleanup: o.cleanup,
        score: o.score,
    }
}

fn reply(generated: Generated) -> proto::GenerateReply {
    proto::GenerateReply {
        generation_id: generated.id,
        seconds: generated.frames as f64 / generated.fps.max(1e-9),
        frames: generated.frames as u32,
        bvh: generated.samples,
        quality: generated.quality.iter().map(quality).collect(),
    }
}

/// The first sample of a one-sample result.
fn motion_reply(generated: Generated) -> proto::MotionReply {
    proto::MotionReply {
        quality: generated.quality.first().map(quality),
        bvh: generated.samples.into_iter().next().unwrap_or_default(),
    }
}

fn quality(q: &QualityReport) -> proto::Quality {
    proto::Quality {
        cleaned_up: q.cleaned_up,
        feet: q.feet as u32,
        planted: q.planted,
        foot_skating: q.foot_skating,
        foot_flight: q.foot_flight,
        ground_penetration: q.ground_penetration,
        jitter: q.jitter,
        max_step: q.max_step,
        body_height: q.body_height,
        real: q.real.as_ref().map(|r| proto::RealMotion {
            subject: r.subject.clone(),
            clips: r.clips as u32,
            jitter: r.jitter,
            foot_skating: r.foot_skating,
            foot_flight: r.foot_flight,
            body_height: r.body_height,
        }),
        jitter_ratio: q.jitter_ratio,
        text_similarity: q.text_similarity,
    }
}

fn clip(c: anymo_store::ClipRow) -> proto::Clip {
    proto::Clip {
        id: c.id,
        path: c.source_path,
        skeleton_id: c.skeleton_id,
        source: c.source,
        licence: c.licence,
        subject: c.subject,
        fps: c.fps,
        frames: c.frames,
        split: c.split,
        captions: c.captions,
    }
}

fn some_text(text: String) -> Option<String> {
    Some(text).filter(|t| !t.trim().is_empty())
}

#[tonic::async_trait]
impl Anymo for AnymoService {
    async fn health(&self, _: Request<proto::HealthRequest>) -> Result<Response<proto::HealthReply>, Status> {
        let (clips, _) = self.state.store.clips_signature().await.map_err(ApiError::from)?;
        let searchable = self.state.search.searchable() as i64;
        Ok(Response::new(proto::HealthReply {
            status: "ok".into(),
            version: env!("CARGO_PKG_VERSION").into(),
            clips,
            searchable_clips: searchable,
        }))
    }

    async fn generate(
        &self,
        request: Request<proto::GenerateRequest>,
    ) -> Result<Response<proto::GenerateReply>, Status> {
        self.state.keys.check(Access::Generate, key(&request).as_deref())?;
        let r = request.into_inner();
        let skeleton = match r.skeleton {
            Some(proto::generate_request::Skeleton::SkeletonBvh(text)) => SkeletonSource::Bvh(text.into_bytes()),
            Some(proto::generate_request::Skeleton::SkeletonId(id)) => SkeletonSource::Stored(id),
            None => return Err(ApiError::bad_request("send skeleton_bvh or skeleton_id").into()),
        };
        let made = generation::generate(&self.state, r.prompt, r.seconds, skeleton, sampling(r.sampling)).await?;
        Ok(Response::new(reply(made)))
    }

    async fn edit(&self, request: Request<proto::EditRequest>) -> Result<Response<proto::GenerateReply>, Status> {
        self.state.keys.check(Access::Generate, key(&request).as_deref())?;
        let r = request.into_inner();
        let edit = match proto::edit_request::Kind::try_from(r.kind) {
            Ok(proto::edit_request::Kind::Inpaint) => Edit::Inpaint { from: r.from_seconds, to: r.to_seconds },
            Ok(proto::edit_request::Kind::Continue) => Edit::Continue { seconds: r.seconds },
            _ => return Err(ApiError::bad_request("kind must be INPAINT or CONTINUE").into()),
        };
        let clip = ClipSource::Bvh(r.clip_bvh.into_bytes());
        let made = generation::edit(&self.state, clip, r.prompt, edit, sampling(r.sampling)).await?;
        Ok(Response::new(reply(made)))
    }

    async fn transfer(&self, request: Request<proto::TransferRequest>) -> Result<Response<proto::MotionReply>, Status> {
        let r = request.into_inner();
        let made = generation::transfer(
            &self.state,
            ClipSource::Bvh(r.clip_bvh.into_bytes()),
            SkeletonSource::Bvh(r.target_bvh.into_bytes()),
            r.cleanup,
        )
        .await?;
        Ok(Response::new(motion_reply(made)))
    }

    async fn tokenize(
        &self,
        request: Request<proto::TokenizeRequest>,
    ) -> Result<Response<proto::TokenizeReply>, Status> {
        let r = request.into_inner();
        let file = generation::tokenize(&self.state, ClipSource::Bvh(r.clip_bvh.into_bytes())).await?;
        let windows = file
            .tokens
            .codes
            .iter()
            .map(|w| proto::TokenWindow {
                steps: w.len() as u32,
                layers: w.first().map_or(0, Vec::len) as u32,
                codes: w.iter().flatten().copied().collect(),
            })
            .collect();
        let json = serde_json::to_string(&file).map_err(ApiError::internal)?;
        Ok(Response::new(proto::TokenizeReply { tokens_json: json, windows, model: file.model }))
    }

    async fn detokenize(
        &self,
        request: Request<proto::DetokenizeRequest>,
    ) -> Result<Response<proto::MotionReply>, Status> {
        let r = request.into_inner();
        let tokens: TokenFile = serde_json::from_str(&r.tokens_json)
            .map_err(|e| ApiError::bad_request(format!("tokens_json is not a tokens file: {e}")))?;
        let to = SkeletonSource::Bvh(r.target_bvh.into_bytes());
        let made = generation::detokenize(&self.state, tokens, to, r.cleanup).await?;
        Ok(Response::new(motion_reply(made)))
    }

    async fn search(&self, request: Request<proto::SearchRequest>) -> Result<Response<proto::SearchReply>, Status> {
        let r = request.into_inner();
        let f = r.filter.unwrap_or_default();
        let params = SearchParams {
            q: some_text(r.text),
            like_clip: r.like_clip_id,
            licence: f.licence,
            subject: f.subject,
            source: f.source,
            skeleton: f.skeleton,
            min_seconds: f.min_seconds,
            max_seconds: f.max_seconds,
            limit: Some(if r.limit == 0 { 10 } else { r.limit as usize }),
            offset: Some(r.offset as usize),
        };
        let like = r.like_bvh.map(|text| ClipSource::Bvh(text.into_bytes()));
        let page = search(&self.state, params, like).await?;
        let hits = page
            .hits
            .into_iter()
            .map(|h| proto::SearchHit {
                rank: h.rank as u32,
                clip_id: h.id,
                path: h.path,
                caption: h.caption,
                subject: h.subject,
                source: h.source,
                licence: h.licence,
                seconds: h.seconds,
                score: h.score,
            })
            .collect();
        Ok(Response::new(proto::SearchReply { hits, candidates: page.candidates as u64 }))
    }

    async fn list_clips(
        &self,
        request: Request<proto::ListClipsRequest>,
    ) -> Result<Response<proto::ListClipsReply>, Status> {
        let r = request.into_inner();
        let limit = if r.limit == 0 { 50 } else { r.limit.min(500) } as i64;
        let clips = self.state.store.list_clips(r.after_id, limit).await.map_err(ApiError::from)?;
        Ok(Response::new(proto::ListClipsReply { clips: clips.into_iter().map(clip).collect() }))
    }

    async fn get_clip(&self, request: Request<proto::GetClipRequest>) -> Result<Response<proto::ClipReply>, Status> {
        let r = request.into_inner();
        let found = self.state.store.clip(r.id).await.map_err(ApiError::from)?;
        let found = found.ok_or_else(|| ApiError::not_found(format!("no clip {}", r.id)))?;
        let bvh = if r.with_bvh {
            let bytes = self.state.store.clip_bvh(r.id).await.map_err(ApiError::from)?.unwrap_or_default();
            String::from_utf8_lossy(&bytes).into_owned()
        } else {
            String::new()
        };
        Ok(Response::new(proto::ClipReply { clip: Some(clip(found)), bvh }))
    }

    async fn list_skeletons(
        &self,
        _: Request<proto::ListSkeletonsRequest>,
    ) -> Result<Response<proto::ListSkeletonsReply>, Status> {
        let skeletons = self.state.store.skeletons().await.map_err(ApiError::from)?;
        let skeletons = skeletons
            .into_iter()
            .map(|s| proto::Skeleton {
                id: s.id,
                fingerprint: s.fingerprint,
                joints: s.joint_count,
                clips: s.clips,
                labels: s.labels,
            })
            .collect();
        Ok(Response::new(proto::ListSkeletonsReply { skeletons }))
    }
}
